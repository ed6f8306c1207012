"""Hypothesis on every `_core` binding (issue 24 item 8), in a child process so a crash is a
finding, not the end of pytest: random shapes, dtypes, NaN/Inf, huge and negative sizes, unknown
options. Every call ends in a result or a ValueError / TypeError / OverflowError (pybind11's
conversion errors); any other exception or a crash fails. CI: 60 examples per campaign (about
1,800 calls); ``pytest -m fuzz tests/robust`` runs 2,000 (about 60,000 calls) and prints the
counts. The second campaign draws consistent shapes, so the calls reach the numerical kernels.

The Python API gets the same treatment (tests/robust/_fuzz_api_child.py: models, preprocessing,
records, metrics, orders, segments, units, column maps), where a named error is a ValueError:
CI 20 examples per campaign (about 500 calls); the long campaign 2,000 (about 50,000)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

CHILD = Path(__file__).with_name("_fuzz_core_child.py")
API_CHILD = Path(__file__).with_name("_fuzz_api_child.py")


def _campaign(examples: int, child: Path = CHILD) -> dict:
    r = subprocess.run([sys.executable, str(child), str(examples)], capture_output=True,
                       text=True, timeout=3600, env=dict(os.environ))
    lines = r.stdout.splitlines()
    assert r.returncode == 0, (f"child died ({r.returncode}) in "
                               f"{lines[-1] if lines else '?'}: {r.stderr[-1500:]}")
    counts = json.loads(lines[-1])
    print(json.dumps(counts))
    other = {k: v for k, v in counts.items() if k.startswith("other:")}
    assert not other, other
    return counts


def test_bindings_raise_only_named_errors():
    counts = _campaign(60)
    assert counts["calls"] >= 60 * 30
    assert counts.get("ok", 0) > 0          # the campaign reaches working calls too


@pytest.mark.fuzz
def test_bindings_long_campaign():
    _campaign(int(os.environ.get("CDAM_FUZZ_EXAMPLES", "2000")))


def test_python_api_raises_only_named_errors():
    counts = _campaign(20, API_CHILD)
    assert counts["calls"] >= 20 * 25
    assert counts.get("ok", 0) > 0


@pytest.mark.fuzz
def test_python_api_long_campaign():
    _campaign(int(os.environ.get("CDAM_FUZZ_API_EXAMPLES", "2000")), API_CHILD)
