#!/usr/bin/env bash
# Installs everything cdam_core needs on a fresh Debian 12 machine (apt packages included),
# creates .venv and builds the package into it. Idempotent: a second run only rebuilds.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PKGS=(build-essential cmake ninja-build pkg-config libeigen3-dev doctest-dev
          python3-venv python3-dev
          gcc-arm-none-eabi libnewlib-arm-none-eabi libstdc++-arm-none-eabi-newlib qemu-system-arm)
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing apt packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv with $($PY --version)"
  $PY -m venv .venv
fi
VPIP=".venv/bin/python -m pip"
$VPIP install -q --upgrade pip
$VPIP install -q "scikit-build-core>=0.10" "pybind11>=2.12" cmake ninja
echo "setup: building and installing cdam_core into .venv"
$VPIP install -q --no-build-isolation -Cbuild-dir=build/release ".[test]"
.venv/bin/python -c "import cdam_core, cdam_core._core; print('setup: cdam_core', cdam_core.__version__, 'ready')"
