#!/usr/bin/env bash
# The test command: set-up, the C++ unit tests (ctest), then every pytest test once (including
# those marked slow, so CI runs the long soak tests exactly once; the long fuzz campaigns,
# marked fuzz, run by hand: pytest -m fuzz tests/robust).
set -euo pipefail
cd "$(dirname "$0")/.."
# each phase prints the seconds since the start (the CI budget: under 20 minutes in all)
phase() { echo "== [$SECONDS s] $1"; }
phase "set-up"
bash scripts/setup.sh --tests    # the firmware tools too: the firmware tests run here
phase "C++ unit tests (ctest) and a hypothesis pass over _core, under AddressSanitizer + UBSan"
bash scripts/sanitize.sh
phase "Python tests (pytest)"
# Two workers (the machine's two cores), one test file per worker at a time (--dist loadfile:
# a file's module fixtures build once; the longest files first, tests/conftest.py, so that no
# worker idles at the end); then the wall-clock load tests (marked realtime) alone.
# -rs: why each skip; --durations: the slowest (CI budget). numpy's BLAS on one thread per
# worker: two workers on two cores each with a multi-threaded BLAS oversubscribe the machine
# (an analysis through residual.analyse measured 40 s against 12 s with one BLAS thread); the
# CLI and the fleet's tasks already limit it the same way (threadpoolctl).
OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 \
.venv/bin/python -m pytest -m "not fuzz and not soak and not realtime" -n 2 --dist loadfile \
  --no-loadscope-reorder \
  -q -rs --durations=30 -p no:cacheprovider "$@" tests
phase "Python wall-clock load tests (pytest -m realtime, alone on the machine)"
.venv/bin/python -m pytest -m "realtime and not fuzz and not soak" -q -rs -p no:cacheprovider \
  "$@" tests || [ $? -eq 5 ]   # 5: none selected (arguments that pick other tests)
phase "done"
