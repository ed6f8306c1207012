#!/usr/bin/env bash
# The main job: set-up, then the paper's experiment on the built-in simulator with a report
# (until the simulator lands: a demo that identifies a small known system end to end).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if .venv/bin/cdam --help | grep -q " paper "; then
  .venv/bin/cdam paper --out reports/paper "$@"
else
  .venv/bin/cdam demo "$@"
fi
