#!/usr/bin/env bash
# The main job: set-up (the package only: no firmware tools; no root needed when a compiler
# and python3-venv are there; apt/pip output in build/setup.log), then the paper's experiment
# on the built-in simulator with a report in reports/paper.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if .venv/bin/cdam --help | grep -q " paper "; then
  .venv/bin/cdam paper --out reports/paper "$@"
else
  .venv/bin/cdam demo "$@"
fi
