# The tile accumulation of an update (included by ext/_kernel.pyx, whose tabulated
# kernel, key helpers, prefetching block lookup and cimports it uses): the (tile,
# sample) pairs sorted by tile, each tile's samples laid out row by row and summed in
# the thread's scratch tile in double precision, then added to the blocks once per
# cell.


cdef struct Row:
    # one row of a sample's support in the tile: its cells rx, rx + 1, ... (x offsets
    # in the tile) in the bricks from `cell` (the alpha of the row's first brick, at the
    # row's y and z), and r2 at the row's first cell inside the support's box with its
    # first difference; the first `skip` of those cells lie before the tile (r2 is
    # carried over them, nothing written), the next `count` are the row's in the tile
    double* cell
    long rx
    long skip
    long count
    double r2
    double dr


cdef enum:
    _ROWS = 32              # rows laid out before their cells are summed


cdef long _add_rows(const Row* rows, int n_rows, int kind, double wk, double y,
                    double ddr, size_t beta_off) noexcept nogil:
    """Add a sample's kernel over its rows: alpha if kind 1 (label 1), beta (`beta_off`
    further) if kind 0 (label 0), both (times y and 1 - y) if kind 2; returns the
    number of cells inside the support."""
    cdef int m
    cdef long j, rx, updates = 0
    cdef double r2, dr, k, x, dx, ddx = ddr * _TABLE
    cdef double* cell
    for m in range(n_rows):
        cell = rows[m].cell + (beta_off if kind == 0 else 0)
        rx = rows[m].rx
        r2 = rows[m].r2
        dr = rows[m].dr
        # r2 along the row by second differences: r2(d0 + res) = r2 + dr,
        # dr(d0 + res) = dr + 2 p00 res^2
        if kind != 2:
            # binary labels: every cell of the row gets wk k(min(r2, 1)), which is +0
            # (no change) outside the support, without a branch. r2 and its differences
            # are carried times _TABLE (a power of two: the same sums, scaled exactly)
            x = r2 * _TABLE
            dx = dr * _TABLE
            for j in range(rows[m].skip):
                x += dx
                dx += ddx
            for j in range(rows[m].count):
                updates += x < <double>_TABLE
                cell[(rx >> 2) * 64 + (rx & 3)] += wk * _interpolate(
                    _KERNEL_R2, _below(x, <double>_TABLE))
                x += dx
                dx += ddx
                rx += 1
        else:
            for j in range(rows[m].skip):
                r2 += dr
                dr += ddr
            for j in range(rows[m].count):
                if r2 < 1.0:
                    k = wk * _kernel_r2(r2)
                    cell[(rx >> 2) * 64 + (rx & 3)] += k * y
                    cell[(rx >> 2) * 64 + (rx & 3) + beta_off] += k * (1.0 - y)
                    updates += 1
                r2 += dr
                dr += ddr
                rx += 1
    return updates


cdef long _accumulate_tile(const double* xs, const double* labels, const double* prec,
                           const double* weights, const int32_t* boxes,
                           const int64_t* members, Py_ssize_t m, double sf2, double res,
                           const long* org, const long* dims, double* box,
                           size_t beta_off, uint8_t* touched) noexcept nogil:
    """Add the evidence of the samples `members[0 .. m)` (in that order) to the tile of
    4x4x4 bricks whose lowest key is `org` and size `dims` cells (block-aligned;
    bricks x fastest, 64 alphas each in `box` and their betas `beta_off` further,
    cell c = x | y << 2 | z << 4 by the low two key bits, as BetaBlock), flagging
    the bricks the samples' rows reach; `boxes[6 i ..]` holds sample i's support
    keys (lowest, then highest, per axis). Returns the number of contributions.

    A sample's rows are those of its support in the tile, each laid out from the
    first cell of its support's box (its x-extent is the same whatever tile it is
    cut in: r2 runs over the cells before the tile without writing), so that every
    cell gets the same terms as from one tile holding the whole support. The rows
    are laid out in batches first (their ends need a square root and are
    independent of each other), then their cells summed."""
    cdef Py_ssize_t t, i
    cdef long lo[3]
    cdef long hi[3]
    cdef long ky, kz, row_lo, row_hi, w_lo, w_hi, bx, b0, b1, bz_row, rx
    cdef long x_end = org[0] + dims[0] - 1, y_end = org[1] + dims[1] - 1
    cdef long z_end = org[2] + dims[2] - 1
    cdef size_t kind_off
    cdef double d0, d1, d2, qb, qc, disc, p00, ddr, y, wk
    cdef double q01, q02, q12, ip00, ires = 1.0 / res
    cdef const double* x
    cdef const double* p
    cdef uint64_t brow
    cdef int kind, n_rows, a
    cdef long updates = 0
    cdef long bdx = dims[0] >> 2, bdy = dims[1] >> 2
    cdef Row rows[_ROWS]
    cdef double row_qb[_ROWS]
    cdef double row_qc[_ROWS]
    cdef double row_disc[_ROWS]
    cdef double row_root[_ROWS]
    cdef long ky0, ky1
    cdef int j, ny
    for t in range(m):
        i = members[t]
        x = xs + 3 * i
        p = prec + 9 * i
        for a in range(3):
            lo[a] = boxes[6 * i + a]
            hi[a] = boxes[6 * i + 3 + a]
        y = labels[i]
        # binary labels add to one of alpha and beta only (k * 1 = k, and adding
        # k * 0 = +0 leaves a sum of non-negative terms as it is)
        kind = 1 if y == 1.0 else (0 if y == 0.0 else 2)
        kind_off = beta_off if kind == 0 else 0
        wk = sf2 * weights[i]
        p00 = p[0]
        ip00 = 1.0 / p00
        q01 = p[1] + p[3]
        q02 = p[2] + p[6]
        q12 = p[5] + p[7]
        ddr = 2.0 * p00 * res * res
        n_rows = 0
        ky1 = min(hi[1], y_end)
        for kz in range(max(lo[2], org[2]), min(hi[2], z_end) + 1):
            d2 = (<double>(kz - _MAX_VAL) + 0.5) * res - x[2]
            bz_row = ((kz - org[2]) >> 2) * bdy
            # in chunks of rows: their discriminants and square roots first (no branch,
            # no wait on each square root), then the rows the ellipsoid meets
            ky0 = max(lo[1], org[1])
            while ky0 <= ky1:
                ny = <int>min(ky1 - ky0 + 1, <long>_ROWS)
                for j in range(ny):
                    d1 = (<double>(ky0 + j - _MAX_VAL) + 0.5) * res - x[1]
                    # the row's cells inside the ellipsoid: r2 is quadratic in d0;
                    # widened by a cell each way, the test of r2 < 1 decides
                    qb = 0.5 * q01 * d1 + 0.5 * q02 * d2
                    qc = p[4] * d1 * d1 + q12 * d1 * d2 + p[8] * d2 * d2
                    disc = qb * qb - p00 * (qc - 1.0)
                    row_qb[j] = qb
                    row_qc[j] = qc
                    row_disc[j] = disc
                _sqrt_positive_n(row_disc, row_root, ny)
                for j in range(ny):
                    if not row_disc[j] > 0.0:
                        continue
                    ky = ky0 + j
                    qb = row_qb[j]
                    qc = row_qc[j]
                    disc = row_root[j]
                    row_lo = max(lo[0], _row_end(x[0], -qb - disc, p00, ip00, res, ires,
                                                 False) + _MAX_VAL)
                    row_hi = min(hi[0], _row_end(x[0], -qb + disc, p00, ip00, res, ires,
                                                 True) + _MAX_VAL)
                    # the cells of the row in the tile
                    w_lo = max(row_lo, org[0])
                    w_hi = min(row_hi, x_end)
                    if w_lo > w_hi:
                        continue
                    brow = <uint64_t>((bz_row + ((ky - org[1]) >> 2)) * bdx)
                    # the row's bricks b0 .. b1: up to four flagged without a loop
                    b0 = (w_lo - org[0]) >> 2
                    b1 = (w_hi - org[0]) >> 2
                    touched[brow + <uint64_t>b0] = 1
                    touched[brow + <uint64_t>min(b0 + 1, b1)] = 1
                    touched[brow + <uint64_t>min(b0 + 2, b1)] = 1
                    touched[brow + <uint64_t>b1] = 1
                    for bx in range(b0 + 3, b1):
                        touched[brow + <uint64_t>bx] = 1
                    d0 = (<double>(row_lo - _MAX_VAL) + 0.5) * res - x[0]
                    rows[n_rows].cell = (box + 64 * brow
                                         + <uint64_t>((ky & 3) << 2 | (kz & 3) << 4))
                    rows[n_rows].rx = w_lo - org[0]       # org is block-aligned
                    rows[n_rows].skip = w_lo - row_lo
                    rows[n_rows].count = w_hi - w_lo + 1
                    # the row's first and last bricks, fetched while the other rows are
                    # laid out
                    rx = w_lo - org[0]
                    __builtin_prefetch(rows[n_rows].cell + (rx >> 2) * 64 + kind_off, 1, 3)
                    rx = w_hi - org[0]
                    __builtin_prefetch(rows[n_rows].cell + (rx >> 2) * 64 + kind_off, 1, 3)
                    rows[n_rows].r2 = (p00 * d0 + 2.0 * qb) * d0 + qc
                    rows[n_rows].dr = (2.0 * p00 * d0 + 2.0 * qb + p00 * res) * res
                    n_rows += 1
                    if n_rows == _ROWS:
                        updates += _add_rows(rows, n_rows, kind, wk, y, ddr, beta_off)
                        n_rows = 0
                ky0 += ny
        updates += _add_rows(rows, n_rows, kind, wk, y, ddr, beta_off)
    return updates


cdef void _sort_by_tile(vector[uint64_t]& pairs, vector[uint64_t]& spare,
                       uint64_t n_tiles) noexcept nogil:
    """Sort `pairs` (tile << 32 | position) by tile, stably: least significant digit
    first, 11 bits of the tile a pass, as many passes as `n_tiles` needs."""
    cdef size_t n = pairs.size(), j
    cdef uint64_t shift = 32, d
    cdef size_t count[2048]
    cdef size_t total, c
    spare.resize(n)
    while (n_tiles - 1) >> (shift - 32) and shift < 64:
        memset(count, 0, sizeof(count))
        for j in range(n):
            count[(pairs[j] >> shift) & 2047] += 1
        total = 0
        for d in range(2048):
            c = count[d]
            count[d] = total
            total += c
        for j in range(n):
            d = (pairs[j] >> shift) & 2047
            spare[count[d]] = pairs[j]
            count[d] += 1
        pairs.swap(spare)
        shift += 11


cdef (long, long) _tile_update(
        BetaBlocks* cells, mutex* lock, const double* xs, const double* labels,
        const double* ps, const double* ws, const int32_t* boxes, const int64_t* members,
        Py_ssize_t m, uint64_t tkey, double sf2, double res, const long* org,
        const long* tile, const long* n_tile, double* box, size_t beta_off,
        uint8_t* touched, int* fail) noexcept nogil:
    """Sum the evidence of the samples `members[0 .. m)` over tile `tkey` (in the
    thread's scratch `box` / `touched`, zero before and after), then add it to the
    map's blocks (created under `lock`; every brick of a tile is its own block, so
    the threads never add to the same one). Returns (contributions, cells newly
    reached); sets fail[0] if a block could not be made."""
    cdef long torg[3]
    cdef long tx, ty, tz, updates, fresh = 0
    cdef long bdx = tile[0] >> 2, bdy = tile[1] >> 2
    cdef size_t b, j, n_touched = 0, n_bricks = beta_off >> 6
    cdef int c
    cdef double* al
    cdef double* be
    cdef BetaBlock* blk
    cdef uint32_t bricks[_TILE_BRICKS]
    cdef uint64_t keys[_TILE_BRICKS]
    cdef BetaBlock* blocks[_TILE_BRICKS]
    tx = <long>(tkey % <uint64_t>n_tile[0])
    ty = <long>((tkey // <uint64_t>n_tile[0]) % <uint64_t>n_tile[1])
    tz = <long>(tkey // <uint64_t>(n_tile[0] * n_tile[1]))
    torg[0] = org[0] + tx * tile[0]
    torg[1] = org[1] + ty * tile[1]
    torg[2] = org[2] + tz * tile[2]
    updates = _accumulate_tile(xs, labels, ps, ws, boxes, members, m, sf2, res, torg,
                               tile, box, beta_off, touched)
    # the blocks of the bricks with evidence, looked up together (their index slots
    # and blocks fetched ahead: they are scattered in memory)
    for b in range(n_bricks):
        if touched[b]:
            touched[b] = 0
            bricks[n_touched] = <uint32_t>b
            keys[n_touched] = _block_key(
                torg[0] + 4 * <long>(b % <size_t>bdx),
                torg[1] + 4 * <long>((b // <size_t>bdx) % <size_t>bdy),
                torg[2] + 4 * <long>(b // <size_t>(bdx * bdy)))
            n_touched += 1
    if not _blocks_locked(cells, lock, keys, blocks, n_touched):
        fail[0] = 1
        for j in range(n_touched):
            memset(box + 64 * <size_t>bricks[j], 0, 64 * sizeof(double))
            memset(box + 64 * <size_t>bricks[j] + beta_off, 0, 64 * sizeof(double))
        return updates, 0
    for j in range(n_touched):
        al = box + 64 * <size_t>bricks[j]
        be = al + beta_off
        blk = blocks[j]
        for c in range(64):
            if al[c] != 0.0 or be[c] != 0.0:
                blk.alpha[c] += <float>al[c]
                blk.beta[c] += <float>be[c]
                if not (blk.mask >> c) & 1:
                    blk.mask |= (<uint64_t>1) << c
                    fresh += 1
                al[c] = 0.0
                be[c] = 0.0
    return updates, fresh
