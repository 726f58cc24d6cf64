"""Helpers that several test modules share (the fixtures are in conftest.py)."""

import threading


def share_between_threads(make_map, scans, read, n_readers=3):
    """Insert `scans` into one map from a thread while `n_readers` others call
    ``read(map)`` 50 times each; return that map, one built from `scans` in a single
    thread, and the exceptions the readers raised."""
    shared, errors = make_map(), []

    def write():
        for p, o in scans:
            shared.insert_scan(p, o)

    def reader():
        try:
            for _ in range(50):
                read(shared)
        except Exception as exc:   # pragma: no cover - reported by the caller
            errors.append(exc)

    threads = [threading.Thread(target=write)]
    threads += [threading.Thread(target=reader) for _ in range(n_readers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    sequential = make_map()
    for p, o in scans:
        sequential.insert_scan(p, o)
    return shared, sequential, errors
