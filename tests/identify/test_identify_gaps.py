"""`cdam identify` on a record whose sidecar declares a gap (issue 24: an imported or merged
record's `gapless_rows` / `gaps` were ignored, so predictions and NARX regressors crossed the
gap). The test record is two stretches of a linear system with a 1 s gap between them, declared
the way `cdam merge` / `import-can` write it (`gapless_rows`, nothing inside the gap) and the way
`import-ulog` writes it (`gaps` only, interpolated rows inside the gap). The scores `identify`
reports must equal a plain-numpy computation per segment (least squares, one-step and free-run
predictions restarted at the gap), which differs from one that runs across the gap."""
import json

import numpy as np
import pytest

from cdam_core.cli.main import main
from cdam_core.models import load_model
from cdam_core.record.dataset import read_dataset

RATE = 100.0
A, B = 0.8, 0.5


def _system(u, y0, rng):
    y = np.empty(u.size)
    y[0] = y0
    for k in range(1, u.size):
        y[k] = A * y[k - 1] + B * u[k - 1] + 0.02 * rng.standard_normal()
    return y


def _write(path, t, u, y, side):
    rows = zip(*(np.asarray(v).tolist() for v in (t, u, y)))
    lines = ["t,u,y"] + [f"{a!r},{b!r},{c!r}" for a, b, c in rows]
    path.write_text("\n".join(lines) + "\n")
    path.with_suffix(".json").write_text(json.dumps({"rate": RATE, "inputs": ["u"],
                                                     "outputs": ["y"], **side}))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("gaps")
    rng = np.random.default_rng(5)
    n = 600
    u = rng.uniform(-1, 1, n)
    _write(d / "train.csv", np.arange(n) / RATE, u, _system(u, 0.0, rng), {})
    # two stretches of 200 samples, the second starting at a far other state after a 1 s gap
    u1, u2 = rng.uniform(-1, 1, 200), rng.uniform(-1, 1, 200)
    y1, y2 = _system(u1, 0.0, rng), _system(u2, 6.0, rng)
    t1, t2 = np.arange(200) / RATE, 3.0 + np.arange(200) / RATE
    gap = {"start": float(t1[-1]), "end": float(t2[0])}
    _write(d / "merged.csv", np.r_[t1, t2], np.r_[u1, u2], np.r_[y1, y2],
           {"gapless_rows": [[0, 200], [200, 400]], "gaps": [{"record": "flight", **gap}]})
    # the import-ulog way: grid rows inside the gap, interpolated over it, the gap declared
    ti = np.arange(1, 100) / RATE + t1[-1]
    _write(d / "ulog.csv", np.r_[t1, ti, t2], np.r_[u1, np.interp(ti, [t1[-1], t2[0]],
                                                                   [u1[-1], u2[0]]), u2],
           np.r_[y1, np.interp(ti, [t1[-1], t2[0]], [y1[-1], y2[0]]), y2],
           {"gaps": {"y": [{**gap, "duration": gap["end"] - gap["start"]}]}})
    return d, (u1, y1), (u2, y2)


def _rmse(e):
    return float(np.sqrt(np.mean(np.square(e))))


def _r(a, b):
    return float(np.corrcoef(a, b)[0, 1])


def test_reading_cuts_at_a_declared_gap(files):
    d, (u1, y1), (u2, y2) = files
    for name in ("merged", "ulog"):
        ds = read_dataset(d / f"{name}.csv")
        assert ds.segments == [(0, 200), (200, 400)], name
        np.testing.assert_array_equal(ds.column("y"), np.r_[y1, y2])
    assert read_dataset(d / "ulog.csv").meta["gap_rows_left_out"] == 99


@pytest.mark.parametrize("name", ["merged", "ulog"])
def test_identify_predicts_each_segment_apart(files, name, tmp_path):
    d, (u1, y1), (u2, y2) = files
    out, model = tmp_path / "r.json", tmp_path / "m.json"
    rc = main(["identify", str(d / "train.csv"), "--test", str(d / f"{name}.csv"), "--algo",
               "bp", "--narx", "1,1,1", "--hidden", "2", "--epochs", "5", "--smoothing", "0",
               "--quiet", "--json", str(out), "--save", str(model)])
    assert rc == 0
    res = json.loads(out.read_text())
    base = res["baselines"]["test"]

    # naive: y(t-1) within each segment; the row after the gap has no earlier sample
    meas = np.r_[y1[1:], y2[1:]]
    naive = np.r_[y1[:-1], y2[:-1]]
    assert base["naive"]["one_step"]["y"]["rmse"] == pytest.approx(_rmse(meas - naive), rel=1e-9)
    crossing = np.r_[y1, y2]
    assert abs(_rmse(crossing[1:] - crossing[:-1]) - _rmse(meas - naive)) > 0.05

    # ARX(1, 1, 1) with intercept, least squares on the training record (plain numpy)
    tr = np.loadtxt(d / "train.csv", delimiter=",", skiprows=1)
    ut, yt = tr[:, 1], tr[:, 2]
    X = np.column_stack([yt[:-1], ut[:-1], np.ones(ut.size - 1)])
    a, b, c = np.linalg.lstsq(X, yt[1:], rcond=None)[0]
    one = np.r_[a * y1[:-1] + b * u1[:-1] + c, a * y2[:-1] + b * u2[:-1] + c]
    arx = base["arx"]["one_step"]["y"]
    assert arx["rmse"] == pytest.approx(_rmse(meas - one), rel=1e-9)
    assert arx["r"] == pytest.approx(_r(meas, one), rel=1e-9)

    def free(u, y):                       # restarted from the segment's first measured row
        p = np.empty(u.size)
        p[0] = y[0]
        for k in range(1, u.size):
            p[k] = a * p[k - 1] + b * u[k - 1] + c
        return p[1:]
    fr = np.r_[free(u1, y1), free(u2, y2)]
    assert base["arx"]["free_run"]["y"]["rmse"] == pytest.approx(_rmse(meas - fr), rel=1e-9)

    # the network: its one-step prediction of each segment on its own
    m = load_model(model)
    p = np.r_[m.predict(u1[:, None], y1[:, None], mode="one_step")[1:, 0],
              m.predict(u2[:, None], y2[:, None], mode="one_step")[1:, 0]]
    got = res["algorithms"]["bp"]["runs"][0]["metrics"]["test"]["one_step"]["y"]
    assert got["rmse"] == pytest.approx(_rmse(meas - p), rel=1e-6)


def test_split_refuses_a_gapped_record(files, capsys):
    d = files[0]
    rc = main(["identify", str(d / "merged.csv"), "--split", "0.5", "--algo", "bp", "--quiet"])
    assert rc == 2
    assert "2 segments" in capsys.readouterr().err
