"""Bad invocations of the CLI, each in a subprocess (issue 24 items 5 and 6): the exit code is the
documented one, stderr is one line 'cdam COMMAND: error: ...', no traceback anywhere, and no input
file changes. Input files are written here with plain Python."""
import functools
import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = os.geteuid() == 0 if hasattr(os, "geteuid") else False
# root ignores file permissions: the permission cases then run the child as the unprivileged
# user `nobody` (util-linux setpriv), in a folder that user can reach
DROP = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
FAST = ["--algo", "bp", "--seeds", "1", "--epochs", "2", "--hidden", "2", "--quiet"]


def _record(path: Path, sidecar: dict | None = None, n: int = 400, rate: float = 1000.0):
    lines = ["t,tau,q"]
    for k in range(n):
        t = k / rate
        lines.append(f"{t!r},{math.sin(7 * t)!r},{math.cos(3 * t)!r}")
    path.write_text("\n".join(lines) + "\n")
    if sidecar is not None:
        path.with_suffix(".json").write_text(json.dumps(sidecar))


@pytest.fixture
def d(tmp_path):
    if ROOT:        # pytest's tmp_path is under a 0700 folder of root's: nobody cannot enter
        tmp_path = Path(tempfile.mkdtemp(prefix="cdam-perm-"))
        tmp_path.chmod(0o755)
    _record(tmp_path / "data.csv", {"rate": 1000.0, "inputs": ["tau"], "outputs": ["q"]})
    _record(tmp_path / "other.csv", {"rate": 1000.0})
    _record(tmp_path / "slow.csv", {"rate": 10.0})                     # declared 10 Hz, 1 kHz
    _record(tmp_path / "effstr.csv", {"model": {"effects": "thrust_loss"}})
    _record(tmp_path / "types.csv", {"units": "rad"})
    (tmp_path / "corrupt.csv").write_text("t,tau,q\n0,1,2\n0.001,x1,2\n0.002,1,2\n")
    (tmp_path / "bus.log").write_text("".join(
        f"({1000 + k / 1000:.6f}) can0 201#{k % 8192:04X}000000000000\n" for k in range(50)))
    (tmp_path / "model.json").write_text('{"not": "a model"}\n')
    (tmp_path / "adir").mkdir()
    (tmp_path / "afile").write_text("x\n")
    locked = tmp_path / "locked.csv"
    _record(locked)
    locked.chmod(0)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    yield tmp_path
    locked.chmod(0o644)
    ro.chmod(0o755)
    if ROOT:
        shutil.rmtree(tmp_path)


@functools.lru_cache(maxsize=None)
def _why_not_unprivileged() -> str:
    """Why the child cannot run as `nobody` here ("" when it can)."""
    if shutil.which("setpriv") is None:
        return "util-linux setpriv is missing"
    r = subprocess.run([*DROP, sys.executable, "-c", "import cdam_core.cli.main"],
                       capture_output=True, text=True, timeout=120, cwd="/",
                       env=os.environ.copy())
    return "" if r.returncode == 0 else ("the unprivileged user cannot run the package here "
                                         f"(python, source or extension not readable): "
                                         f"{r.stderr[-300:]}")


def _unprivileged() -> list:
    """The command prefix that runs the child as `nobody` when the tests run as root ([] when
    they do not); skips, with the reason, where that is impossible."""
    if not ROOT:
        return []
    why = _why_not_unprivileged()
    if why:
        pytest.skip(f"running as root (which ignores file permissions) and {why}")
    return DROP


# (name, argv with {d} for the folder, expected exit code, text the message must contain)
CASES = [
    ("output is the input", ["identify", "{d}/data.csv", "--json", "{d}/data.csv", *FAST], 2,
     "is the input"),
    ("output is the input's sidecar", ["identify", "{d}/data.csv", "--json", "{d}/data.json",
                                      *FAST], 2, "sidecar"),
    ("model saved over the input", ["identify", "{d}/data.csv", "--save", "{d}/./data.csv",
                                    *FAST], 2, "is the input"),
    ("two outputs one file", ["identify", "{d}/data.csv", "--json", "{d}/r.json", "--save",
                              "{d}/r.json", *FAST], 2, "also the output"),
    ("output in a missing folder", ["identify", "{d}/data.csv", "--json", "{d}/no/r.json",
                                    *FAST], 3, "does not exist"),
    ("output under a file", ["simulate", "-o", "{d}/afile/f.csv", "--duration", "0.1"], 3,
     "not a folder"),
    ("output is a folder", ["identify", "{d}/data.csv", "--json", "{d}/adir", *FAST], 3,
     "is a folder"),
    ("report folder is an input", ["residual", "{d}/data.csv", "--model", "rigid_axis",
                                   "--report", "{d}/data.csv"], 2, "is the input"),
    ("a folder as input", ["identify", "{d}/adir", *FAST], 2, "adir"),
    ("corrupt CSV", ["identify", "{d}/corrupt.csv", *FAST], 2, "line 3"),
    ("sidecar rate disagrees", ["identify", "{d}/slow.csv", "--inputs", "tau", "--outputs", "q",
                                *FAST], 2, "'rate'"),
    ("sidecar effects a string", ["residual", "{d}/effstr.csv", "--model", "rigid_axis"], 2,
     "model.effects"),
    ("sidecar units a string", ["residual", "{d}/types.csv", "--model", "rigid_axis"], 2,
     "'units'"),
    ("residual --cutoff 0", ["residual", "{d}/data.csv", "--model", "rigid_axis", "--cutoff",
                             "0"], 2, "--cutoff"),
    ("import-can over its log", ["import-can", "{d}/bus.log", "-o", "{d}/bus.log"], 2,
     "is the input"),
    ("import-can grid too large", ["import-can", "{d}/bus.log", "-o", "{d}/j.csv", "--joints",
                                   "1:m1", "--rate", "1e12"], 2, "MAX_GRID_SAMPLES"),
    ("merge over an input", ["merge", "{d}/data.csv", "{d}/other.csv", "-o", "{d}/other.csv"],
     2, "is the input"),
    ("merge rate grid too large", ["merge", "{d}/data.csv", "{d}/other.csv", "-o",
                                   "{d}/m.csv", "--pair", "q:q", "--rate", "1e12"], 2,
     "MAX_GRID_SAMPLES"),
    ("export over the model", ["export-firmware", "{d}/model.json", "-o", "{d}/model.json"], 2,
     "is the input"),
    ("paper --out is a file", ["paper", "--out", "{d}/afile", "--quiet"], 3, "not a folder"),
    ("unreadable input", ["identify", "{d}/locked.csv", *FAST], 3, "ermission"),
    ("read-only output folder", ["identify", "{d}/data.csv", "--json", "{d}/ro/r.json", *FAST],
     3, "not writable"),
]
NEEDS_NON_ROOT = {"unreadable input", "read-only output folder"}


def _hashes(d: Path) -> dict:
    out = {}
    for p in sorted(d.rglob("*")):
        if p.is_file() and os.access(p, os.R_OK):
            out[p.name] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.mark.parametrize("name,argv,code,text", CASES, ids=[c[0] for c in CASES])
def test_bad_invocation_is_one_line_and_touches_no_input(d, name, argv, code, text):
    prefix = _unprivileged() if name in NEEDS_NON_ROOT else []
    before = _hashes(d)
    r = subprocess.run([*prefix, sys.executable, "-m", "cdam_core.cli.main",
                        *[a.format(d=d) for a in argv]],
                       capture_output=True, text=True, timeout=300, env=os.environ.copy(),
                       cwd=d)
    assert "Traceback" not in r.stdout + r.stderr, r.stderr
    assert r.returncode == code, r.stderr
    after = _hashes(d)
    assert {k: after[k] for k in before} == before, "an input file changed"
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"cdam {argv[0]}: error: "), lines[0]
    assert text in lines[0], lines[0]


def test_interrupt_is_exit_130_one_line(d):
    """Ctrl-C during a long identification: exit 130, one line, no traceback, nothing written."""
    import signal
    import time
    argv = ["identify", str(d / "data.csv"), "--algo", "iboa", "--seeds", "1", "--iterations",
            "1000000", "--quiet", "--json", str(d / "r.json")]
    with subprocess.Popen([sys.executable, "-m", "cdam_core.cli.main", *argv],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          env=os.environ.copy()) as p:
        time.sleep(6.0)                                  # past the imports, inside the search
        p.send_signal(signal.SIGINT)
        try:
            out, err = p.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            raise
    assert "Traceback" not in out + err, err
    assert p.returncode == 130, err
    assert err.strip().splitlines() == ["cdam identify: error: interrupted"]
    assert not (d / "r.json").exists()
