"""A reader that stops early (`cdam ... | head`) is not an error: the command completes, writes
its files, exits 0 and prints nothing on stderr."""
import io
import sys

import numpy as np

from cdam_core.cli.main import main


class _ClosedPipe(io.StringIO):
    """stdout whose reader has gone: every write raises BrokenPipeError."""

    def write(self, s):
        raise BrokenPipeError(32, "Broken pipe")


def test_output_into_a_closed_pipe(tmp_path, monkeypatch, capsys):
    t = np.arange(3000) * 1e-3
    rng = np.random.default_rng(0)
    tau = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 3.1 * t)
    q = np.cumsum(np.cumsum(tau) * 1e-3) * 1e-3 + rng.normal(0, 1e-7, t.size)
    np.savetxt(tmp_path / "r.csv", np.column_stack([t, tau, q]), delimiter=",",
               header="t,force,pos", comments="", fmt="%.10g")
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    rc = main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
               "tau=force,q=pos", "--no-free-run", "--report", str(tmp_path / "rep")])
    assert rc == 0
    assert "error" not in capsys.readouterr().err
    assert (tmp_path / "rep" / "index.md").is_file()
