#!/usr/bin/env bash
# Regenerates python/cdam_core/_core.pyi from the built extension with pybind11-stubgen.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/python -m pip install -q pybind11-stubgen
out=$(mktemp -d)
.venv/bin/pybind11-stubgen cdam_core._core -o "$out"
cp "$out/cdam_core/_core.pyi" python/cdam_core/_core.pyi
echo "wrote python/cdam_core/_core.pyi"
