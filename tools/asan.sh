#!/usr/bin/env bash
# `make asan`: build occgp's extensions with AddressSanitizer and UndefinedBehaviorSanitizer
# (liboctomap's asserts off, -DNDEBUG, as in production builds) in a copy of the tree under
# build/asan, run the test suite there with the sanitizer runtimes preloaded, and report
# every sanitizer finding. Exits non-zero when there is one.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
PY="$(cd "$(dirname "$PY")" && pwd)/$(basename "$PY")"   # keep the venv: no symlink resolution
DIR=build/asan
LOGS=$(realpath -m "$DIR/logs")

mkdir -p "$DIR"
# the tracked and new (not ignored) files of the working tree
git ls-files -z --cached --others --exclude-standard -- setup.py pyproject.toml ext occgp tests docs tools \
  | xargs -0 cp -p --parents -t "$DIR"
rm -rf "$LOGS" && mkdir -p "$LOGS"
# the tests find real data in ../shared beside the project: beside the copy too
if [ -d ../shared ] && [ ! -e build/shared ]; then ln -s "$(cd ../shared && pwd)" build/shared; fi

SAN="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
echo "occgp asan: building the extensions with $SAN -DNDEBUG"
(cd "$DIR" && CFLAGS="$SAN -DNDEBUG -g" LDFLAGS="$SAN" "$PY" setup.py -q build_ext --inplace \
  > "$LOGS/build.txt" 2>&1) || { tail -40 "$LOGS/build.txt"; exit 1; }

PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)"
echo "occgp asan: running the test suite (reports to $LOGS)"
set +e
# OCCGP_UNDER_SANITIZER: tools/fuzz.py then sets no address-space limit in its child
# processes (ASan reserves terabytes of shadow address space)
(cd "$DIR" && LD_PRELOAD="$PRELOAD" \
  ASAN_OPTIONS="detect_leaks=0:abort_on_error=0:halt_on_error=1:log_path=$LOGS/asan" \
  UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:log_path=$LOGS/ubsan" \
  OCCGP_UNDER_SANITIZER=1 "$PY" -m pytest -q -p no:cacheprovider "$@")
status=$?
set -e
reports=$(find "$LOGS" -name 'asan.*' -o -name 'ubsan.*' | wc -l)
echo "occgp asan: pytest exit status $status, sanitizer reports: $reports"
if [ "$reports" -gt 0 ]; then
  for f in "$LOGS"/asan.* "$LOGS"/ubsan.*; do [ -e "$f" ] && { echo "== $f"; head -40 "$f"; }; done
  exit 1
fi
exit $status
