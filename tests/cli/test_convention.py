"""One command-line convention (issue 22 item 5): --version, defaults in --help, --json FILE,
--quiet and --report DIR on every command that computes, warnings on stderr."""
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
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


def _commands():
    """(name, parser) of every command and sub-command of `cdam`."""
    import argparse
    from cdam_core.cli.main import build_parser

    out, todo = [], [("cdam", build_parser())]
    while todo:
        name, p = todo.pop()
        out.append((name, p))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                todo += [(f"{name} {n}", sp) for n, sp in a.choices.items()]
    return out


# the commands that compute results (the others convert or record files)
COMPUTING = ["cdam paper", "cdam identify", "cdam residual", "cdam evaluate", "cdam demo",
             "cdam merge", "cdam firmware check", "cdam monitor", "cdam batch"]


def test_every_default_is_shown_in_help():
    cmds = dict(_commands())
    assert set(COMPUTING) <= set(cmds)
    for name, p in cmds.items():
        p.format_help()                                   # renders without error
        fmt = p._get_formatter()
        for a in p._actions:
            if not a.option_strings or a.nargs == 0 or a.default in (None, [], "==SUPPRESS=="):
                continue
            shown = fmt._expand_help(a) if a.help else ""   # the text --help prints
            assert "default" in shown.lower(), f"{name} {a.option_strings[-1]}: default " \
                                               f"{a.default!r} not shown"


@pytest.mark.parametrize("name", COMPUTING)
def test_computing_commands_offer_json_quiet_report(name):
    p = dict(_commands())[name]
    opts = {o for a in p._actions for o in a.option_strings}
    assert {"--json", "--quiet", "--report"} <= opts, f"{name}: {opts}"


def _small_record(d: Path):
    """u a sum of sines, y = tanh(u) + a small cosine: a static map plus an unmodelled term."""
    t = np.arange(600) / 100.0
    u = np.sin(1.3 * t) + 0.5 * np.sin(3.1 * t)
    y = np.tanh(u) + 0.1 * np.cos(7 * t)
    (d / "small.csv").write_text("t,u,y\n" + "".join(
        f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(t.tolist(), u.tolist(), y.tolist())))
    (d / "small.json").write_text('{"inputs": ["u"], "outputs": ["y"]}')
    return t, u, y


def test_identify_without_options_runs_one_algorithm_one_seed_and_leads_with_baselines(tmp_path):
    """The headline is the held-out record's score beside the naive y(t-1) and a least-squares
    linear map, both recomputed here with numpy (no smoothing: --smoothing 0)."""
    import json
    t, u, y = _small_record(tmp_path)
    r = _cdam("identify", tmp_path / "small.csv", "--smoothing", "0", "--json",
              tmp_path / "r.json")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("test record, one step")
    assert [ln.split()[0] for ln in lines[1:4]] == ["IBOA-BP", "naive", "ARX(0,"]
    assert "training fitness" in r.stdout and "not a validation score" in r.stdout
    js = json.loads((tmp_path / "r.json").read_text())
    assert list(js["algorithms"]) == ["iboa"] and js["seeds"] == [0]
    n = 300                                               # --split default 0.5 of 600
    yt, ut = y[n:], u[n:]
    naive = js["baselines"]["test"]["naive"]["one_step"]["y"]
    e = yt[1:] - yt[:-1]
    assert naive["nrmse"] == pytest.approx(np.sqrt(np.mean(e ** 2)) / np.std(yt[1:]), rel=1e-9)
    X = np.column_stack([u[:n], np.ones(n)])
    coef = np.linalg.lstsq(X, y[:n], rcond=None)[0]
    pred = np.column_stack([ut, np.ones(ut.size)]) @ coef
    arx = js["baselines"]["test"]["arx"]["one_step"]["y"]
    assert arx["r"] == pytest.approx(np.corrcoef(pred, yt)[0, 1], rel=1e-9)
    assert arx["rmse"] == pytest.approx(np.sqrt(np.mean((pred - yt) ** 2)), rel=1e-6)


def test_identify_says_whether_the_model_is_below_the_best_baseline(tmp_path):
    """Under each table, one line: the best baseline's mean NRMSE (naive or ARX, whichever is
    lower in the JSON) and whether the model's is below it, recomputed from the JSON."""
    import json
    _small_record(tmp_path)
    r = _cdam("identify", tmp_path / "small.csv", "--smoothing", "0", "--algo", "bp",
              "--hidden", "3", "--epochs", "3", "--json", tmp_path / "r.json")
    assert r.returncode == 0, r.stderr
    js = json.loads((tmp_path / "r.json").read_text())
    model = js["summary"]["bp"]["records"]["test"]["one_step"]["y"]["nrmse"]["mean"]
    base = {"naive": js["baselines"]["test"]["naive"]["one_step"]["y"]["nrmse"],
            "ARX": js["baselines"]["test"]["arx"]["one_step"]["y"]["nrmse"]}
    name = min(base, key=base.get)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("  -> ")]
    assert len(lines) == 1, r.stdout
    assert f"best baseline ({name}" in lines[0] and f", {base[name]:.3f}):" in lines[0]
    assert lines[0].endswith("below" if model < base[name] else "NOT below")
    assert (" NOT below" in lines[0]) == (model >= base[name])


def test_notes_and_progress_stay_off_stdout(tmp_path):
    """Piped (not a TTY): no progress bar at all; notes on stderr, silenced by --quiet."""
    _small_record(tmp_path)
    base = ["identify", tmp_path / "small.csv", "--algo", "bp", "--epochs", "3", "--hidden", "3",
            "--save", tmp_path / "m.json"]
    r = _cdam(*base)
    assert r.returncode == 0, r.stderr
    assert "model:" in r.stderr and "model:" not in r.stdout
    assert "\r" not in r.stderr and "it/s" not in r.stderr        # no tqdm bar into a pipe
    q = _cdam(*base, "--quiet")
    assert q.returncode == 0 and q.stderr == ""


class _Terminal:
    """A stand-in for stderr on a terminal: records what is written."""

    def __init__(self, tty: bool):
        self.tty, self.text = tty, ""

    def isatty(self):
        return self.tty

    def write(self, s):
        self.text += s

    def flush(self):
        pass


@pytest.mark.parametrize("tty,quiet", [(True, False), (True, True), (False, False)])
def test_long_runs_show_elapsed_time_on_a_terminal_only(monkeypatch, tty, quiet):
    """`cdam residual` (about a minute on EMPS) wraps its fit in elapsed_ticker: on a terminal
    the task and the seconds elapsed, redrawn in place and erased at the end; nothing with
    --quiet or into a pipe or file."""
    import time
    from types import SimpleNamespace
    from cdam_core.cli.common import elapsed_ticker
    err = _Terminal(tty)
    monkeypatch.setattr(sys, "stderr", err)
    with elapsed_ticker(SimpleNamespace(command="residual", quiet=quiet), "fitting",
                        every=0.05):
        time.sleep(0.4)
    if tty and not quiet:
        ticks = err.text.split("\r")[1:]
        assert len(ticks) >= 3 and ticks[0] == "cdam residual: fitting ... 0 s elapsed"
        assert err.text.endswith("\r\033[K")                  # the line erased at the end
    else:
        assert err.text == ""
    src = (Path(__file__).resolve().parents[2] / "python" / "cdam_core" / "cli"
           / "residual.py").read_text()
    assert "elapsed_ticker(args" in src
