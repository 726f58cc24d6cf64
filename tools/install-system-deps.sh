#!/usr/bin/env bash
# Install what occgp needs from Debian when it is missing: liboctomap-dev (found
# through pkg-config), a C++ compiler, the Python headers and venv support. Runs
# apt-get through sudo when not root. Does nothing when everything is present.
set -euo pipefail

PYTHON=${PYTHON:-python3}
need=()

pkg-config --version >/dev/null 2>&1 || need+=(pkg-config)
pkg-config --exists octomap 2>/dev/null || need+=(liboctomap-dev)
command -v g++ >/dev/null 2>&1 || need+=(g++)
command -v graph2tree >/dev/null 2>&1 || need+=(octomap-tools)
if ! "$PYTHON" - <<'PY' >/dev/null 2>&1
import os, sysconfig
raise SystemExit(not os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")))
PY
then
  need+=(python3-dev)
fi
"$PYTHON" -c "import ensurepip, venv" >/dev/null 2>&1 || need+=(python3-venv)

if [ ${#need[@]} -eq 0 ]; then
  exit 0
fi

if ! command -v apt-get >/dev/null 2>&1; then
  echo "occgp: missing system packages (${need[*]}) and no apt-get to install them;" >&2
  echo "install liboctomap (with its pkg-config file), a C++ compiler and the Python headers." >&2
  exit 1
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO=sudo
  else
    echo "occgp: need root or sudo to apt-get install ${need[*]}" >&2
    exit 1
  fi
fi

echo "occgp: installing ${need[*]} with apt-get"
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -qq
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}"
