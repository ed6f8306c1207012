"""`cdam batch` (issue [fleet]): on a 2-worker LocalCluster the table and the model files are
byte for byte those of the serial run; a corrupt record among good ones is reported with its
error while the others complete; a cancelled batch leaves the completed rows written; the rows
equal what `cdam identify` computes on its own for the same record, split, algorithm and seed
(another code path: cli.identify -> evaluate.compare)."""
import hashlib
import json
import math
import os
import subprocess
import sys
import threading
from pathlib import Path

import pandas as pd
import pytest

from cdam_core.fleet.spec import load_spec, parse_spec

pytest.importorskip("dask.distributed")

OPTIONS = {"hidden": 3, "epochs": 3, "iterations": 2, "population": 6, "smoothing": 1,
           "narx": [1, 1, 1], "threads": 1}


def _record(path: Path, phase: float, n: int = 240):
    lines = ["t,u,y"]
    for k in range(n):
        t = k / 100.0
        u = math.sin(1.3 * t + phase) + 0.5 * math.sin(3.1 * t)
        lines.append(f"{t!r},{u!r},{math.tanh(u) + 0.1 * math.cos(7 * t + phase)!r}")
    path.write_text("\n".join(lines) + "\n")
    path.with_suffix(".json").write_text('{"inputs": ["u"], "outputs": ["y"]}')


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "recs").mkdir()
    for k in range(2):
        _record(tmp_path / "recs" / f"good{k}.csv", phase=0.7 * k)
    (tmp_path / "recs" / "bad.csv").write_text("t,u,y\n0,1,2\n0.01,x,2\n")   # not a number
    return tmp_path


def _spec(folder, **kw):
    doc = {"command": "identify", "records": ["recs/*.csv"], "algorithms": ["bp", "iboa"],
           "seeds": 2, "folds": 2, "options": OPTIONS, **kw}
    (folder / "spec.json").write_text(json.dumps(doc))
    return load_spec(folder / "spec.json", base=folder)


def _table(out):
    return pd.read_parquet(out / "results.parquet").drop(columns="seconds")


def _files(out):
    return {p.name: p.read_bytes() for p in sorted((out / "models").iterdir())}


def test_two_workers_equal_the_serial_run_and_a_corrupt_record_is_reported(folder, client):
    from cdam_core.fleet.graph import run_batch
    spec = _spec(folder)
    assert len(spec.tasks()) == 3 * 2 * 2 * 2
    run_batch(spec, folder / "serial")
    rows = run_batch(spec, folder / "dask", client)
    a, b = _table(folder / "serial"), _table(folder / "dask")
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert _files(folder / "serial") == _files(folder / "dask")
    assert len(_files(folder / "dask")) == 16
    bad = a[a.record.str.endswith("bad.csv")]
    assert len(bad) == 8 and (bad.status == "error").all()
    assert bad.error.str.contains("bad.csv").all() and bad.model.isna().all()
    good = a[~a.record.str.endswith("bad.csv")]
    assert (good.status == "ok").all() and good["test.free_run.y.r"].notna().all()
    js = json.loads((folder / "dask" / "results.json").read_text())
    assert js["status"] == {"ok": 16, "error": 8, "cancelled": 0}
    assert [r["task"] for r in js["rows"]] == [r["task"] for r in rows] == list(a.task)


def test_rows_equal_cdam_identify_on_the_same_split(folder):
    """folds = 1 is `cdam identify --split`: the same fitness and held-out r, computed by the
    identify command in a subprocess."""
    from cdam_core.fleet.graph import run_batch
    spec = _spec(folder, records=["recs/good1.csv"], algorithms=["bp"], folds=1,
                 options={**OPTIONS, "split": 0.6})
    rows = run_batch(spec, folder / "out")
    o = OPTIONS
    r = subprocess.run([sys.executable, "-m", "cdam_core", "identify",
                        str(folder / "recs" / "good1.csv"), "--split", "0.6", "--algo", "bp",
                        "--seeds", "2", "--hidden", str(o["hidden"]), "--epochs",
                        str(o["epochs"]), "--smoothing", str(o["smoothing"]), "--narx", "1,1,1",
                        "--json", str(folder / "id.json"), "--quiet"],
                       capture_output=True, text=True, env=os.environ.copy(), timeout=300)
    assert r.returncode == 0, r.stderr
    runs = json.loads((folder / "id.json").read_text())["algorithms"]["bp"]["runs"]
    assert [x["seed"] for x in runs] == [row["seed"] for row in rows] == [0, 1]
    for row, run in zip(rows, runs):
        assert row["fitness"] == run["fitness"]
        for mode in ("one_step", "free_run"):
            assert row[f"test.{mode}.y.r"] == run["metrics"]["test"][mode]["y"]["r"]


def test_cancelled_batch_keeps_the_completed_rows(folder, client):
    from cdam_core.fleet.graph import run_batch
    (folder / "long").mkdir()
    for k in range(2):
        _record(folder / "long" / f"long{k}.csv", phase=0.3 * k, n=2000)
    spec = _spec(folder, records=["long/*.csv"], algorithms=["iboa"], seeds=6, folds=1,
                 options={**OPTIONS, "iterations": 30, "population": 20, "hidden": 10,
                          "epochs": 30, "goal": 0.0})          # about 0.1 s a task here
    run_batch(spec, folder / "serial")
    # one worker held by a task waiting on an event: the batch runs one task at a time on the
    # other, so when the first row arrives most tasks have not started
    from dask.distributed import Event
    first, _ = sorted(client.scheduler_info()["workers"])
    hold = client.submit(lambda: Event("fleet-test-hold").wait(120), workers=[first], pure=False)
    stop = threading.Event()
    try:
        rows = run_batch(spec, folder / "cut", client, stop=stop, on_row=lambda row: stop.set())
    finally:
        Event("fleet-test-hold", client=client).set()
        hold.result(timeout=60)
    status = [r["status"] for r in rows]
    assert status.count("ok") >= 1 and status.count("cancelled") >= 1, status
    cut, full = _table(folder / "cut"), _table(folder / "serial")
    done = cut.status == "ok"
    pd.testing.assert_frame_equal(cut[done], full[done], check_exact=True,
                                  check_dtype=False)   # NaN of cancelled rows: float columns
    assert cut[~done].model.isna().all() and (cut[~done].status == "cancelled").all()
    saved = _files(folder / "cut")
    assert sorted(saved) == sorted(Path(m).name for m in cut[done].model)


def test_derived_seeds_come_from_the_task_alone(folder):
    spec = _spec(folder, seed_rule="derived")
    for t in spec.tasks():
        text = f"{Path(t.record).name}|{t.algorithm}|{t.seed_index}|{t.fold}".encode()
        assert t.seed == int.from_bytes(hashlib.sha256(text).digest()[:4], "little")
    assert len({t.seed for t in spec.tasks()}) == len(spec.tasks())


@pytest.mark.parametrize("doc,field", [
    ({"command": "fly", "records": "recs/*.csv"}, "spec.command"),
    ({"command": "identify", "records": "nothing/*.csv"}, "spec.records"),
    ({"command": "identify", "records": "recs/*.csv", "seeds": 0}, "spec.seeds"),
    ({"command": "identify", "records": "recs/*.csv", "algorithms": ["sgd"]}, "spec.algorithms"),
    ({"command": "identify", "records": "recs/*.csv", "options": {"hiden": 3}},
     "spec.options.hiden"),
    ({"command": "identify", "records": "recs/*.csv", "options": {"split": 1.5}},
     "spec.options.split"),
    ({"command": "evaluate", "records": "recs/*.csv"}, "spec.model"),
    ({"command": "crossfold", "records": "recs/*.csv", "folds": ["loop"]}, "spec.folds"),
    ({"command": "identify", "records": "recs/*.csv", "extra": 1}, "extra"),
    ({"command": "crossfold", "records": "recs/*.csv", "seeds": 3}, "spec.seeds"),
    ({"command": "paper", "records": "recs/*.csv"}, "spec.records"),
    ({"command": "paper", "sections": ["loop"]}, "spec.sections"),
    ({"command": "paper", "sections": ["narx"], "options": {"narx": None}}, "spec.sections"),
    ({"command": "paper", "options": {"rate": 300}}, "spec.options"),     # 300 Hz: not 1000/q
    ({"command": "paper", "options": {"map": "x"}}, "spec.options.map"),
    ({"command": "residual", "records": "recs/*.csv"}, "spec.options.model"),
    ({"command": "residual", "records": "recs/*.csv",
      "options": {"model": "rigid_axis", "alpha": 2}}, "spec.options.alpha"),
    ({"command": "residual", "records": "recs/*.csv",
      "options": {"model": "rigid_axis", "map": "tau=force"}}, "spec.options.map"),
    ({"command": "residual", "records": "recs/*.csv",
      "options": {"model": "rigid_axis", "estimator": "ols"}}, "spec.options.estimator"),
    ({"command": "residual", "records": "recs/*.csv",
      "options": {"model": "rigid_axis", "stick_slip": True}}, "spec.options.stick_slip"),
    ({"command": "residual", "records": "recs/*.csv",
      "options": {"model": "rigid_axis", "output_error": True, "estimator": "idim-ls"}},
     "spec.options.output_error"),
])
def test_bad_spec_names_the_field(folder, doc, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        parse_spec(doc, base=folder)


def test_cli_bad_spec_is_one_line_exit_2(folder):
    (folder / "spec.json").write_text('{"command": "identify", ')
    r = subprocess.run([sys.executable, "-m", "cdam_core", "batch", str(folder / "spec.json"),
                        "--out", str(folder / "o"), "--serial"], capture_output=True, text=True,
                       env=os.environ.copy(), timeout=120)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("cdam batch: error: ")
    assert "not valid JSON" in r.stderr
    assert not (folder / "o").exists()                      # "nothing written"


def test_shared_records_missing_name_the_folder_and_the_variable(folder, monkeypatch):
    monkeypatch.setenv("CDAM_SHARED_DATA", str(folder / "no-shared"))
    with pytest.raises(ValueError, match="spec.records") as e:
        parse_spec({"command": "crossfold", "records": "shared:nanodrone/*.parquet"}, base=folder)
    assert str(folder / "no-shared") in str(e.value) and "CDAM_SHARED_DATA" in str(e.value)


def test_cli_local_cluster_runs_and_reports_the_failed_record(folder):
    _spec(folder, algorithms=["bp"], seeds=1, folds=1)
    r = subprocess.run([sys.executable, "-m", "cdam_core", "batch", "spec.json",
                        "--out", "o", "--workers", "2", "--quiet", "--json", "s.json",
                        "--report", "rep"], cwd=folder,
                       capture_output=True, text=True, env=os.environ.copy(), timeout=300)
    assert r.returncode == 1, r.stderr          # done, but incomplete
    assert r.stderr == ""                       # --quiet: no notes, no bar
    assert "2 of 3 task(s) done" in r.stdout and "bad.csv" in r.stdout
    t = pd.read_parquet(folder / "o" / "results.parquet")
    assert len(t) == 3
    js = json.loads((folder / "s.json").read_text())
    assert js["status"] == {"ok": 2, "error": 1, "cancelled": 0}
    assert [f["task"] for f in js["summary"]["failed"]] == list(t.task[t.status == "error"])
    groups = {Path(g["record"]).name: g for g in js["summary"]["groups"]}
    assert groups["bad.csv"]["ok"] == 0 and groups["bad.csv"]["metrics"] == {}
    ok = t[t.record.str.endswith("good0.csv")].iloc[0]
    m = groups["good0.csv"]["metrics"]["test.free_run.y.r"]
    assert (m["n"], m["mean"], m["std"], m["min"], m["max"]) == (
        1, ok["test.free_run.y.r"], 0.0, ok["test.free_run.y.r"], ok["test.free_run.y.r"])
    md = (folder / "rep" / "index.md").read_text()
    assert "## Failed or cancelled tasks" in md and "non-numeric cell" in md
    assert "(../o/results.parquet)" in md and (folder / "rep" / "index.html").is_file()


def test_cli_interrupt_is_exit_130_and_keeps_the_completed_rows(folder):
    """Ctrl-C while a task runs: exit 130, one line, the row that completed (the corrupt
    record's error) written, the running task listed as cancelled."""
    import signal
    import time
    _spec(folder, records=["recs/bad.csv", "recs/good0.csv"], algorithms=["iboa"], seeds=1,
          folds=1, options={**OPTIONS, "iterations": 1000000})
    p = subprocess.Popen([sys.executable, "-m", "cdam_core", "batch", "spec.json", "--out", "o",
                          "--workers", "1"], cwd=folder, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        first = p.stderr.readline()           # the note: the cluster is up, tasks submitted
        time.sleep(8.0)                       # the corrupt record's task is done by then
        p.send_signal(signal.SIGINT)
        err = p.communicate(timeout=60)[1]
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, first + err
    assert "2 task(s) on 1 worker(s)" in first
    assert err.strip().splitlines() == ["cdam batch: error: interrupted"]
    t = pd.read_parquet(folder / "o" / "results.parquet")
    assert list(t.status) == ["error", "cancelled"]
    assert "bad.csv" in t.error[0]


def test_evaluate_scores_a_saved_model_on_every_record(folder, client):
    """evaluate: one row per record; the free-run RMSE recomputed here with numpy from the
    model's own free-run prediction on the record as read and smoothed (1 pass)."""
    import numpy as np

    from cdam_core import load_model
    from cdam_core.fleet.graph import run_batch
    from cdam_core.preprocess import smooth_pair
    from cdam_core.record.dataset import read_dataset
    run_batch(_spec(folder, records=["recs/good0.csv"], algorithms=["bp"], seeds=1, folds=1),
              folder / "fit")
    model = folder / "fit" / "models" / "0000-good0-bp-s0-f0.json"
    doc = {"command": "evaluate", "records": ["recs/*.csv"], "model": str(model)}
    spec = parse_spec(doc, base=folder)
    rows = run_batch(spec, folder / "ev", client)
    assert [r["status"] for r in rows] == ["error", "ok", "ok"]
    serial = run_batch(spec, folder / "ev_serial")
    assert [{**r, "seconds": 0} for r in serial] == [{**r, "seconds": 0} for r in rows]
    m = load_model(model)
    for row in rows[1:]:
        ds = read_dataset(row["record"])
        U, Y = smooth_pair(ds.select(["u"]), ds.select(["y"]), OPTIONS["smoothing"])
        P = m.predict(U, Y, mode="free_run")
        e = (P[m.t0:, 0] - Y[m.t0:, 0])
        assert row["free_run.y.rmse"] == pytest.approx(float(np.sqrt(np.mean(e ** 2))),
                                                       rel=1e-12)
