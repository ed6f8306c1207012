"""`cdam batch` beyond identify: the paper's comparison equals `cdam paper`'s own serial run
(cdam_core.paper.run_paper, figures left out), run by run and in its summary; residual equals
`cdam residual --json` on the same record; the aggregate equals pandas' group statistics of
the table; progress shows only on a terminal; at most a window of tasks is on the cluster;
and (slow) a scheduler and workers started by hand give the serial table."""
import json
import math
import os
import pickle
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cdam_core.fleet.spec import parse_spec
from cdam_core.fleet.tasks import flatten

pytest.importorskip("dask.distributed")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "residual"))
from test_residual_synth_data import rigid_axis_record  # noqa: E402

TINY = {"duration": 2.0, "iterations": 3, "epochs": 3, "hidden": 5, "population": 6}
ENV = os.environ.copy()


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


@pytest.fixture(scope="module")
def paper_runs(tmp_path_factory, request):
    """`cdam paper`'s result on the tiny configuration (2 seeds; its figures not drawn)."""
    import cdam_core.paper.pipeline as pl
    from cdam_core.paper import PaperConfig, run_paper
    mp = pytest.MonkeyPatch()
    mp.setattr(pl, "_figures", lambda *a, **k: {"preprocessing": [], "convergence": [],
                                               "identified": []})
    try:
        cfg = PaperConfig(seeds=2, duration=TINY["duration"], iterations=TINY["iterations"],
                          lm_epochs=TINY["epochs"], hidden=TINY["hidden"],
                          population=TINY["population"])       # threads=2, cdam paper's
        return run_paper(cfg, tmp_path_factory.mktemp("paper"), progress=False)
    finally:
        mp.undo()


def test_paper_batch_equals_cdam_paper_run_by_run(paper_runs, tmp_path, client):
    from cdam_core.fleet.graph import run_batch
    spec = parse_spec({"command": "paper", "seeds": 2, "options": TINY})
    rows = run_batch(spec, tmp_path / "b", client)       # 2 processes, 1 core thread a task
    assert [(r["section"], r["algorithm"], r["seed"]) for r in rows] == [
        (s, a, k) for s in ("static", "narx", "hybrid") for a in ("iboa", "boa", "cabc")
        for k in (0, 1)]
    compared = 0
    for row in rows:
        assert row["status"] == "ok", row["error"]
        run = paper_runs["sections"][row["section"]]["algorithms"][row["algorithm"]]["runs"][
            row["seed"]]
        ref = {k: v for k, v in run.items()
               if k not in ("seed", "curve_mse", "lm_mse", "metrics", "seconds")}
        ref.update(run["metrics"])
        for k, v in flatten(ref).items():
            assert _same(row.get(k), v), (row["task"], k, row.get(k), v)
            compared += 1
    assert compared > 18 * 100
    # the aggregate: cdam paper's summary (numpy mean and std, ddof 1) over the same seeds
    doc = json.loads((tmp_path / "b" / "results.json").read_text())
    for g in doc["summary"]["groups"]:
        s = paper_runs["sections"][g["section"]]["summary"][g["algorithm"]]
        assert g["ok"] == 2
        for rec, modes in s["records"].items():
            for mode, outs in modes.items():
                for o, ms in outs.items():
                    for k, a in ms.items():
                        m = g["metrics"][f"{rec}.{mode}.{o}.{k}"]
                        if a["mean"] is None:
                            assert m["n"] < 2
                            continue
                        assert m["mean"] == pytest.approx(a["mean"], rel=1e-12, abs=1e-15)
                        assert m["std"] == pytest.approx(a["std"], rel=1e-9, abs=1e-15)
    # the saved models are the fitted ones: the static network's one-step r on the test
    # record, recomputed here with numpy from the model file's prediction
    from cdam_core import load_model
    from cdam_core.paper.records import prepare_data, simulate_records
    data = prepare_data(simulate_records(0, TINY["duration"]), 5, 200.0)
    row = rows[0]
    m = load_model(tmp_path / "b" / row["model"])
    P = np.vstack([m.predict(seg.U) for seg in data.test])
    Y = np.vstack([seg.Y for seg in data.test])
    j = data.outputs.index("q1")
    assert row["test.one_step.q1.r"] == pytest.approx(np.corrcoef(P[:, j], Y[:, j])[0, 1],
                                                      rel=1e-9)


def test_aggregate_equals_pandas_group_statistics(tmp_path):
    """The summary of a serial identify batch against pandas' groupby on the table."""
    from cdam_core.fleet.graph import run_batch
    (tmp_path / "r").mkdir()
    for k in range(2):
        _rigid_csv(tmp_path / "r" / f"a{k}.csv", seed=k + 1, duration=2.0)
    spec = parse_spec({"command": "identify", "records": ["r/*.csv"], "algorithms": ["bp"],
                       "seeds": 3, "folds": 2,
                       "options": {"hidden": 3, "epochs": 3, "smoothing": 1, "narx": [1, 1, 1],
                                   "inputs": ["force"], "outputs": ["pos"]}}, base=tmp_path)
    run_batch(spec, tmp_path / "o")
    t = pd.read_parquet(tmp_path / "o" / "results.parquet")
    doc = json.loads((tmp_path / "o" / "results.json").read_text())
    assert len(doc["summary"]["groups"]) == 2
    for g in doc["summary"]["groups"]:
        sub = t[t.record == g["record"]]
        assert g["tasks"] == g["ok"] == len(sub) == 6
        for name in ("fitness", "test.free_run.pos.rmse", "test.one_step.pos.r", "seconds"):
            col = sub[name].astype(float)
            m = g["metrics"][name]
            assert m["n"] == 6
            assert m["mean"] == pytest.approx(col.mean(), rel=1e-12)
            assert m["std"] == pytest.approx(col.std(ddof=1), rel=1e-9)
            assert (m["min"], m["max"]) == (col.min(), col.max())


def _rigid_csv(path, **kw):
    rec = rigid_axis_record(**kw)
    np.savetxt(path, np.column_stack([rec["t"], rec["tau"], rec["q"]]), delimiter=",",
               header="t,force,pos", comments="", fmt="%.10g")


def test_residual_batch_equals_cdam_residual(tmp_path, client):
    from cdam_core import load_model
    from cdam_core.cli.main import main
    from cdam_core.fleet.graph import run_batch
    (tmp_path / "r").mkdir()
    _rigid_csv(tmp_path / "r" / "axis.csv", seed=2, Fc=1.5, duration=4.0)
    (tmp_path / "r" / "broken.csv").write_text("t,force,pos\n0,1,2\n0.01,x,2\n")
    assert main(["residual", str(tmp_path / "r" / "axis.csv"), "--model", "rigid_axis",
                 "--map", "tau=force,q=pos", "--json", str(tmp_path / "o.json"), "--save",
                 str(tmp_path / "m.json")]) == 0
    js = json.loads((tmp_path / "o.json").read_text())
    spec = parse_spec({"command": "residual", "records": ["r/*.csv"],
                       "options": {"model": "rigid_axis", "map": {"tau": "force", "q": "pos"}}},
                      base=tmp_path)
    rows = run_batch(spec, tmp_path / "b", client)
    good, bad = rows                                       # axis.csv, broken.csv
    assert bad["status"] == "error" and "broken.csv" in bad["error"] and bad["model"] is None
    assert good["status"] == "ok", good["error"]
    assert good["effects"] == ",".join(f"{f['effect']}@{f['channel']}" for f in js["findings"])
    assert good["effects"] == "coulomb_friction@tau"          # the effect simulated
    ref = flatten({k: js[k] for k in ("declared_error", "error_final", "final_parameters")})
    assert ref and all(_same(good[k], v) for k, v in ref.items())
    a, b = load_model(tmp_path / "m.json"), load_model(tmp_path / "b" / good["model"])
    assert a.parameters() == b.parameters() and b.kind == "greybox"


def test_progress_bar_only_on_a_terminal(tmp_path):
    (tmp_path / "r").mkdir()
    _rigid_csv(tmp_path / "r" / "a.csv", seed=1, duration=1.0)
    (tmp_path / "s.json").write_text(json.dumps(
        {"command": "identify", "records": ["r/a.csv"], "algorithms": ["bp"], "seeds": 2,
         "options": {"hidden": 2, "epochs": 2, "smoothing": 1, "narx": [1, 1, 1],
                     "inputs": ["force"], "outputs": ["pos"]}}))
    cmd = [sys.executable, "-m", "cdam_core", "batch", "s.json", "--serial"]
    r = subprocess.run(cmd + ["--out", "o1"], cwd=tmp_path, capture_output=True, text=True,
                       env=ENV, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stderr.splitlines() == ["cdam batch: 2 task(s), serial, this process"]
    import fcntl
    import struct
    import termios
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal's size
    p = subprocess.Popen(cmd + ["--out", "o2"], cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=slave, env=ENV)
    os.close(slave)
    err = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        err += chunk
    p.communicate(timeout=120)
    os.close(master)
    assert p.returncode == 0
    assert b"batch:" in err and b"0/2" in err, err      # tqdm's bar, on the terminal only


def test_a_window_of_tasks_on_the_cluster_and_nothing_left_after(tmp_path, client):
    """Workers read their records (the task shipped is a path and options, the same size for
    any record length); at most ``window`` tasks are known to the scheduler at a time (all 9
    would be at the first result without the window) and none once the batch is done."""
    from cdam_core.fleet.graph import run_batch
    (tmp_path / "r").mkdir()
    _rigid_csv(tmp_path / "r" / "short.csv", seed=1, duration=1.0)
    t = np.arange(200_000) * 1e-3                        # 200 s at 1 kHz, written plainly
    np.savetxt(tmp_path / "r" / "long_.csv", np.column_stack([t, np.sin(t), np.cos(t)]),
               delimiter=",", header="t,force,pos", comments="", fmt="%.6g")
    opts = {"hidden": 2, "epochs": 2, "smoothing": 1, "narx": [1, 1, 1], "inputs": ["force"],
            "outputs": ["pos"]}
    spec = parse_spec({"command": "identify", "records": ["r/*.csv"], "algorithms": ["bp"],
                       "seeds": 4, "options": opts}, base=tmp_path)
    size = {Path(t.record).name: len(pickle.dumps(t)) for t in spec.tasks()}
    assert abs(size["short.csv"] - size["long_.csv"]) <= 8 and max(size.values()) < 2000

    def ours(dask_scheduler):
        return sum(str(k).startswith("cdam-batch-") for k in dask_scheduler.tasks)

    seen = []
    (tmp_path / "s").mkdir()
    spec = parse_spec({"command": "identify", "records": ["r/short.csv"], "algorithms": ["bp"],
                       "seeds": 9, "options": opts}, base=tmp_path)
    rows = run_batch(spec, tmp_path / "o", client, window=2,
                     on_row=lambda row: seen.append(client.run_on_scheduler(ours)))
    assert [r["status"] for r in rows] == ["ok"] * 9
    assert len(seen) == 9 and max(seen) <= 2, seen
    deadline = time.time() + 10
    while client.run_on_scheduler(ours) and time.time() < deadline:
        time.sleep(0.1)
    assert client.run_on_scheduler(ours) == 0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_hand_started_scheduler_and_workers_give_the_serial_table(tmp_path):
    """`dask scheduler` and `dask worker` started as the README shows; `cdam batch
    --scheduler` gives the --serial table (the paper kind, tiny)."""
    (tmp_path / "s.json").write_text(json.dumps(
        {"command": "paper", "seeds": 2, "algorithms": ["iboa", "cabc"],
         "sections": ["static", "narx"], "options": TINY}))
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                              "127.0.0.1", "--port", str(port), "--dashboard-address", ":0"],
                             env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    work = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", addr,
                             "--nworkers", "2", "--nthreads", "1", "--no-dashboard"],
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        cmd = [sys.executable, "-m", "cdam_core", "batch", "s.json", "--quiet"]
        a = subprocess.run(cmd + ["--out", "hand", "--scheduler", addr], cwd=tmp_path,
                           capture_output=True, text=True, env=ENV, timeout=120)
        assert a.returncode == 0, a.stderr
        b = subprocess.run(cmd + ["--out", "serial", "--serial"], cwd=tmp_path,
                           capture_output=True, text=True, env=ENV, timeout=120)
        assert b.returncode == 0, b.stderr
    finally:
        for p in (work, sched):
            p.terminate()
        for p in (work, sched):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
    x, y = (pd.read_parquet(tmp_path / d / "results.parquet") for d in ("hand", "serial"))
    drop = [c for c in x.columns if c == "seconds" or c.startswith("seconds.")]
    assert len(x) == 8
    pd.testing.assert_frame_equal(x.drop(columns=drop), y.drop(columns=drop), check_exact=True)
    models = sorted(p.name for p in (tmp_path / "hand" / "models").iterdir())
    assert len(models) == 8
    assert all((tmp_path / "hand" / "models" / n).read_bytes()
               == (tmp_path / "serial" / "models" / n).read_bytes() for n in models)


_FAULTS = """
import resource, sys
import numpy as np
from cdam_core.fleet.tasks import worker_malloc
done = worker_malloc() if sys.argv[1] == "fix" else None
x = np.ones(1)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(300):
    x = np.ones(131072) * 2.0          # 1 MiB temporaries, as a rollout makes
after = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
print(done, after - before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_worker_malloc_undoes_the_frozen_mmap_threshold():
    """With Dask's MALLOC_TRIM_THRESHOLD_=65536 each 1 MiB temporary is a fresh mmap: 256
    page faults each; worker_malloc (run by every task) makes them reuse the heap."""
    env = {**ENV, "MALLOC_TRIM_THRESHOLD_": "65536"}
    env.pop("MALLOC_MMAP_THRESHOLD_", None)
    got = {}
    for mode in ("plain", "fix"):
        r = subprocess.run([sys.executable, "-c", _FAULTS, mode], capture_output=True,
                           text=True, env=env, timeout=120)
        assert r.returncode == 0, r.stderr
        got[mode] = r.stdout.split()
    assert got["fix"][0] == "True"
    assert int(got["plain"][1]) > 300 * 200         # a page fault per 4 KiB page, each time
    assert int(got["fix"][1]) < 300 * 20
