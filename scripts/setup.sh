#!/usr/bin/env bash
# Sets up cdam_core on a Debian 12 machine: creates .venv and builds the package into it.
#
#   bash scripts/setup.sh              the package only: no root needed when a C++ compiler and
#                                      python3-venv are there (Eigen comes from the PyPI package
#                                      cmeel-eigen when the system has none; CMake and Ninja
#                                      from PyPI)
#   bash scripts/setup.sh --firmware   also the ARM toolchain with newlib, QEMU and Eigen for
#                                      the firmware (`cdam firmware check`; about 2.4 GB, apt)
#   bash scripts/setup.sh --tests      everything the test command needs: the firmware tools,
#                                      doctest, headless Chromium (report pages) and .[test]
#
# apt and pip output goes to build/setup.log; the terminal gets one line a step. Missing apt
# packages are installed with apt-get (as root, else through sudo); none missing, no root.
# Idempotent: a second run on the same commit (no uncommitted change) builds nothing.
set -euo pipefail
cd "$(dirname "$0")/.."

FIRMWARE=0
TESTS=0
for a in "$@"; do
  case "$a" in
    --firmware) FIRMWARE=1 ;;
    --tests) TESTS=1; FIRMWARE=1 ;;
    *) echo "setup: unknown option $a (use --firmware or --tests)" >&2; exit 2 ;;
  esac
done

mkdir -p build
LOG="$PWD/build/setup.log"
: > "$LOG"
fail() { echo "setup: $1 failed; the last lines of $LOG:" >&2; tail -n 25 "$LOG" >&2; exit 1; }

APT_PKGS=(g++ python3-venv python3-dev)
# cmake on PATH for the firmware build (`cdam firmware` runs `cmake`, not .venv/bin/cmake);
# git for the tests that clone the checkout (tests/test_fresh_clone.py, test_readme.py)
[ $FIRMWARE -eq 1 ] && APT_PKGS+=(gcc-arm-none-eabi libnewlib-arm-none-eabi
                                  libstdc++-arm-none-eabi-newlib qemu-system-arm libeigen3-dev
                                  cmake)
[ $TESTS -eq 1 ] && APT_PKGS+=(doctest-dev chromium-headless-shell git)
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: apt packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  { $SUDO apt-get update -qq \
    && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends \
       "${missing[@]}"; } >> "$LOG" 2>&1 || fail "apt-get install"
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv with $($PY --version)"
  $PY -m venv .venv >> "$LOG" 2>&1 || fail "python -m venv"
fi
VPIP=".venv/bin/python -m pip"
EXTRA=""
[ $TESTS -eq 1 ] && EXTRA="[test]"
# What .venv was built from: the commit's tree when the checkout has no uncommitted change
# (else nothing: a tarball or a modified tree is always rebuilt). The same tree already built
# with these extras is not built again (main.sh run twice, then test.sh: seconds, not minutes).
STAMP=.venv/cdam-setup.stamp
SRC=""
if [ "$(git rev-parse --show-toplevel 2>/dev/null)" = "$PWD" ] \
   && [ -z "$(git status --porcelain -- . ':(exclude).venv' 2>/dev/null)" ]; then
  SRC="$(git rev-parse 'HEAD^{tree}')"
fi
if [ -n "$SRC" ] && [ -f "$STAMP" ] \
   && { grep -qxF "$SRC $EXTRA" "$STAMP" || { [ -z "$EXTRA" ] && grep -q "^$SRC " "$STAMP"; }; } \
   && .venv/bin/python -c "import cdam_core._core" > /dev/null 2>&1; then
  echo "setup: cdam_core$EXTRA already built from this commit's tree (remove $STAMP to rebuild)"
else
  echo "setup: building and installing cdam_core$EXTRA into .venv (a few minutes the first time)"
  rm -f "$STAMP"
  { $VPIP install --upgrade pip \
    && $VPIP install "scikit-build-core>=0.10" "pybind11>=2.12" "cmeel-eigen>=3.4" cmake ninja \
    && $VPIP install --no-build-isolation -Cbuild-dir=build/release ".$EXTRA"; } >> "$LOG" 2>&1 \
    || fail "pip install"
  if [ -n "$SRC" ]; then echo "$SRC $EXTRA" > "$STAMP"; fi
fi
.venv/bin/python -c "import cdam_core, cdam_core._core; print('setup: cdam_core', cdam_core.__version__, 'ready (log: build/setup.log)')"
if [ $FIRMWARE -eq 1 ]; then
  .venv/bin/python -c "
from cdam_core.firmware import toolchain_available
why = toolchain_available()
print('setup: firmware tools ' + ('missing: ' + why if why else 'ready'))"
fi
