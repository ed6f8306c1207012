#!/usr/bin/env bash
# The C++ unit tests (ctest: doctest's cdam_tests and the host/embeddable fence) and a
# hypothesis pass over every _core binding (tests/robust/_fuzz_core_child.py), all under
# AddressSanitizer + UBSan: one build (build/sanitize, -O1, pybind11's link-time optimisation
# kept: without it the build took 441 s against 344 s, session 17), the unit tests run once,
# sanitized. The sanitized extension is
# loaded into the venv's Python (libasan and libstdc++ preloaded, so that ASan intercepts C++
# throws; leak checks off: CPython itself does not free everything).
# Part of scripts/test.sh; EXAMPLES (default 60) sets the hypothesis budget.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/cmake -S . -B build/sanitize -G Ninja -DCDAM_PYTHON=ON -DCDAM_TESTS=ON \
  -DCDAM_SANITIZE=ON -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE=-O1 \
  -DPython_EXECUTABLE="$PWD/.venv/bin/python" > build/sanitize.log 2>&1 \
  || { cat build/sanitize.log; exit 1; }
.venv/bin/cmake --build build/sanitize -j2 >> build/sanitize.log 2>&1 \
  || { cat build/sanitize.log; exit 1; }
(cd build/sanitize && ../../.venv/bin/ctest --output-on-failure > ../sanitize-ctest.log 2>&1) \
  || { cat build/sanitize-ctest.log; exit 1; }
tail -n 3 build/sanitize-ctest.log
LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libstdc++.so)" \
  ASAN_OPTIONS=detect_leaks=0 \
  UBSAN_OPTIONS=print_stacktrace=1 CDAM_CORE_EXT_DIR="$PWD/build/sanitize/cdam_core" \
  PYTHONPATH="$PWD/python" .venv/bin/python tests/robust/_fuzz_core_child.py "${EXAMPLES:-60}" \
  | tail -n 1
