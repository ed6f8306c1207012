"""One command-line convention (issue 22 item 5): --version, defaults in --help, --json FILE,
--quiet and --report DIR on every command that computes, warnings on stderr."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest


def _cdam(*argv, timeout=300):
    return subprocess.run([sys.executable, "-m", "cdam_core", *map(str, argv)],
                          capture_output=True, text=True, timeout=timeout, env=os.environ.copy())


def test_version_is_the_package_version():
    init = Path(__file__).resolve().parents[2] / "python" / "cdam_core" / "__init__.py"
    want = re.search(r'^__version__ = "([^"]+)"', init.read_text(), re.M).group(1)
    r = _cdam("--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"cdam {want}"
