"""The README's example runner (``python -m cdam_core.cli.example``) ends a failure as every
`cdam` command does: one stderr line naming the problem and an exit code, no traceback."""
import subprocess
import sys
import os

from cdam_core.cli import example


def test_missing_emps_record_is_one_line_naming_where_it_looked(tmp_path, monkeypatch, capsys):
    import cdam_core.record.realdata.emps as emps
    monkeypatch.setattr(emps, "emps_path", lambda name="DATA_EMPS": tmp_path / f"{name}.mat")
    monkeypatch.setattr(emps, "repo_data_dir", lambda: tmp_path / "repo")
    monkeypatch.setattr(emps, "shared_data_dir", lambda: tmp_path / "shared")
    rc = example.main(["emps", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("cdam example emps: error: EMPS record DATA_EMPS")
    assert str(tmp_path / "shared" / "emps") in err[0] and "CDAM_SHARED_DATA" in err[0]
    assert not (tmp_path / "out" / "index.md").exists()


def test_unknown_example_is_a_usage_error():
    r = subprocess.run([sys.executable, "-m", "cdam_core.cli.example", "nosuch", "out"],
                       capture_output=True, text=True, timeout=120, env=os.environ.copy())
    assert r.returncode == 2 and "invalid choice" in r.stderr and "Traceback" not in r.stderr
