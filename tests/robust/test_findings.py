"""Findings of issue 24 that had no test of their own (the audit in docs/ROBUSTNESS.md): each case
is the issue's own example. In-process through `cdam`'s main, except the NARX lags that once
crashed the interpreter, which run in a child."""
import hashlib
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from cdam_core.cli.main import main


def _record(path, sidecar=None, n=400, rate=1000.0):
    lines = ["t,tau,q"] + [f"{k / rate!r},{math.sin(7 * k / rate)!r},{math.cos(3 * k / rate)!r}"
                           for k in range(n)]
    path.write_text("\n".join(lines) + "\n")
    if sidecar is not None:
        path.with_suffix(".json").write_text(json.dumps(sidecar))
    return path


def _one_line(capsys, command):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"cdam {command}: error: "), err
    return err


def test_huge_narx_lag_from_the_command_line_is_a_named_error(tmp_path):
    """`cdam identify X.csv --algo iboa --narx 1,2,2147483647` (and `cdam paper`) segfaulted:
    nk + nb - 1 overflowed int. In a child, so a crash fails the test."""
    data = _record(tmp_path / "x.csv", {"inputs": ["tau"], "outputs": ["q"]})
    code = ("import sys\nfrom cdam_core.cli.main import main\n"
            "for argv in ([%r, '--algo', 'iboa', '--narx', '1,2,2147483647', '--quiet'],\n"
            "             ['--out', %r, '--narx', '1,2,2147483647', '--quiet']):\n"
            "    print(main([('identify' if len(argv) == 6 else 'paper'), *argv]), flush=True)\n"
            % (str(data), str(tmp_path / "paper")))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300, env=os.environ.copy())
    assert r.returncode == 0, f"child died ({r.returncode}): {r.stderr[-1000:]}"
    assert r.stdout.split() == ["2", "2"], r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 2 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith("cdam identify: error: --narx") and "nk" in lines[0], lines[0]
    assert lines[1].startswith("cdam paper: error: --narx") and "nk" in lines[1], lines[1]


def test_export_firmware_refuses_a_huge_lag_before_building_anything(tmp_path, capsys):
    """A model file with `narx: [2, 100000000, 1]` made export-firmware build 6e8 strings."""
    from cdam_core.models import save_model
    from cdam_core.models.network import BPNetwork
    rng = np.random.default_rng(0)
    U = rng.uniform(-1, 1, (200, 1))
    path = tmp_path / "m.json"
    save_model(path, BPNetwork(hidden=2, epochs=1, seed=1, narx=(2, 1, 1)).fit(
        U, np.cumsum(U, axis=0)), inputs=["u"], outputs=["y"])
    doc = json.loads(path.read_text())
    doc["model"]["narx"] = [2, 100000000, 1]
    body = {k: v for k, v in doc.items() if k != "checksum"}
    doc["checksum"] = {"sha256": hashlib.sha256(json.dumps(
        body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()}
    path.write_text(json.dumps(doc))
    t0 = time.perf_counter()
    assert main(["export-firmware", str(path), "-o", str(tmp_path / "m.hpp")]) == 2
    assert time.perf_counter() - t0 < 10
    assert "model.narx[1]" in _one_line(capsys, "export-firmware")
    assert not (tmp_path / "m.hpp").exists()


def test_merge_refuses_a_declared_rate_far_from_the_data(tmp_path, capsys):
    """A declared 10 Hz rate on 1 kHz data made `merge` drop 99 % of the samples silently."""
    a = _record(tmp_path / "a.csv", {"rate": 1000.0})
    b = _record(tmp_path / "b.csv", {"rate": 10.0})
    assert main(["merge", str(a), str(b), "-o", str(tmp_path / "m.csv"), "--pair", "q:q"]) == 2
    err = _one_line(capsys, "merge")
    assert "'rate'" in err and "declares 10 Hz" in err
    assert not (tmp_path / "m.csv").exists()


def test_a_json_that_is_not_a_model_is_named(tmp_path, capsys):
    """Model type confusion: any JSON handed as a model file."""
    data = _record(tmp_path / "x.csv", {"inputs": ["tau"], "outputs": ["q"]})
    for doc in ('{"not": "a model"}', "[1, 2]", '"text"', '{"format": 2, "kind": 7}'):
        (tmp_path / "m.json").write_text(doc)
        assert main(["evaluate", str(tmp_path / "m.json"), str(data), "--quiet"]) == 2
        assert "m.json" in _one_line(capsys, "evaluate")


def test_outputs_are_checked_before_computing(tmp_path, capsys):
    """Output paths were checked only after the computation: an unwritable output now ends a
    run that would take hours at once."""
    data = _record(tmp_path / "x.csv", {"inputs": ["tau"], "outputs": ["q"]})
    t0 = time.perf_counter()
    assert main(["identify", str(data), "--algo", "iboa", "--iterations", "100000000",
                 "--json", str(tmp_path / "missing" / "r.json"), "--quiet"]) == 3
    assert time.perf_counter() - t0 < 10
    assert "does not exist" in _one_line(capsys, "identify")


@pytest.mark.parametrize("exc, code, text", [
    (MemoryError(), 3, "out of memory"),
    (PermissionError(13, "Permission denied", "x.csv"), 3, "x.csv: Permission denied"),
    (IsADirectoryError(21, "Is a directory", "out"), 3, "out: Is a directory"),
    (NotADirectoryError(20, "Not a directory", "f/x"), 3, "f/x: Not a directory"),
    (FileExistsError(17, "File exists", "rep"), 3, "rep: File exists"),
    (ZeroDivisionError("float division by zero"), 2, "division by zero"),
])
def test_error_types_that_ended_in_tracebacks_are_one_line(monkeypatch, capsys, exc, code,
                                                           text):
    """Every PermissionError, IsADirectoryError, NotADirectoryError, FileExistsError,
    MemoryError and ZeroDivisionError ended in a traceback: raised from inside a command, each
    is now one line with its documented exit code."""
    import cdam_core.cli.simulate as sim

    def fails(args):
        raise exc
    monkeypatch.setattr(sim, "run", fails)
    assert main(["simulate", "-o", "never.csv"]) == code
    assert text in _one_line(capsys, "simulate")


def test_import_ulog_grid_above_the_limit_is_refused(tmp_path, capsys):
    """`import-ulog --rate` sized its grid from the data until MemoryError or OOM."""
    from cdam_core.record.realdata import shared_data_dir
    log = shared_data_dir() / "ulog" / "sample_log_small.ulg"
    if not log.is_file():
        pytest.skip("shared ULog data not found")
    assert main(["import-ulog", str(log), "-o", str(tmp_path / "u.csv"), "--rate", "1e12"]) == 2
    assert "MAX_GRID_SAMPLES" in _one_line(capsys, "import-ulog")
    assert not (tmp_path / "u.csv").exists()


def test_arx_fit_on_values_near_1e300_is_a_named_error():
    """Found by the Python-API fuzz (session 5): ArxModel.fit on values near 1e300 ended in
    numpy's LinAlgError ('SVD did not converge', naming nothing) or hung in pinv on an
    overflowed normal matrix. In a child with a timeout, so a hang fails the test."""
    code = ("import numpy as np, cdam_core\n"
            "U = np.full((40, 1), 1e300); U[::3] = -1e300; Y = U.copy()\n"
            "try:\n"
            "    cdam_core.ArxModel((1, 1, 1)).fit(U, Y)\n"
            "    print('fitted')\n"
            "except ValueError as e:\n"
            "    print(type(e).__name__, e)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, env=os.environ.copy())
    assert r.returncode == 0, r.stderr[-1000:]
    assert r.stdout.startswith("ValueError U, Y: values too large"), r.stdout + r.stderr
