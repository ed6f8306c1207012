"""The nano-drone benchmark's flights through the loader, checked against the raw Parquet
columns; the exclusion rules on synthetic flights; several records as segments."""
import numpy as np
import pandas as pd
import pytest

from cdam_core.models import ArxModel
from cdam_core.record.dataset import Dataset, write_dataset
from cdam_core.record.realdata import shared_data_dir
from cdam_core.record.realdata.nanodrone import (INPUTS, STATES, flight_exclusions,
                                                 load_nanodrone, trajectory_type)
from cdam_core.record.stack import stack_records

FOLDER = shared_data_dir() / "nanodrone"
SQUARE = FOLDER / "square_20251017_run2.parquet"
MULTISINE4 = FOLDER / "multisine_20251017_run4.parquet"
real = pytest.mark.skipif(
    not SQUARE.is_file(),
    reason=f"nano-drone flights not found at {FOLDER}: they stay outside the repository (no "
           f"licence file); set CDAM_SHARED_DATA to the folder holding nanodrone/")


@real
def test_loader_matches_raw_columns_and_leaves_out_gaps():
    raw = pd.read_parquet(SQUARE)
    ds = load_nanodrone(SQUARE)
    assert ds.inputs == INPUTS and ds.outputs == STATES and ds.rate == 100.0
    assert trajectory_type(SQUARE) == "square" and ds.meta["trajectory"] == "square"
    rows = np.searchsorted(raw["t"].to_numpy(), ds.t)
    assert np.array_equal(raw["t"].to_numpy()[rows], ds.t)
    for k in range(4):   # eRPM x 2 pi / 360, the benchmark repository's conversion
        np.testing.assert_allclose(ds.column(f"w{k + 1}"),
                                   raw[f"m{k + 1}_erpm"].to_numpy()[rows] * np.pi / 180,
                                   rtol=1e-15)
    for c in STATES:
        assert np.array_equal(ds.column(c), raw[c].to_numpy()[rows])
    motors = raw[[f"m{k}_erpm" for k in range(1, 5)]].to_numpy()
    nan_t = raw["t"].to_numpy()[np.isnan(motors).any(axis=1)]
    assert nan_t.size > 0 and not np.isin(nan_t, ds.t).any()
    ex = ds.meta["excluded"]
    assert sum(e["samples"] for e in ex) == len(raw) - len(ds)
    assert sum(e["reason"] == "NaN motor speed" for e in ex) == nan_t.size
    assert ds.t[0] > 0.1                      # the takeoff, on the ground, is left out
    assert any("ground contact" in e["reason"] and e["t_stop"] == raw["t"].iloc[-1]
               for e in ex)                   # and the landing
    # no segment spans a left-out row: inside a segment the raw rows are consecutive
    for a, b in ds.segments:
        assert np.all(np.diff(rows[a:b]) == 1)
    assert len(ds.segments) - 1 == np.sum(np.diff(rows) > 1)   # every gap is a seam


@real
def test_the_diverging_estimate_of_multisine_run4_is_left_out():
    ds = load_nanodrone(MULTISINE4)
    div = [e for e in ds.meta["excluded"] if "diverging" in e["reason"]]
    assert len(div) == 1 and div[0]["t_stop"] == pytest.approx(64.89)
    assert 63.0 < div[0]["t_start"] < 63.5
    assert ds.t[-1] < div[0]["t_start"]
    glitch = [e for e in ds.meta["excluded"] if e["reason"] == "implausible motor speed"]
    raw = pd.read_parquet(MULTISINE4)
    w = raw[[f"m{k}_erpm" for k in range(1, 5)]].to_numpy() * np.pi / 180
    bad_t = raw["t"].to_numpy()[np.any(w > 4400, axis=1)]          # the 33,036 rad/s readings
    assert bad_t.size == 3 and [(g["t_start"], g["t_stop"]) for g in glitch] == \
        [(bad_t[0], bad_t[-1])]
    assert ds.column("w1").max() < 3000


def _flight(n=600, dt=0.01, drift=None):
    """A synthetic hover-and-move flight: position the exact integral of velocity; ``drift``
    (a, b, m/s) adds a position drift the velocity does not have on rows a..b."""
    t = np.arange(n) * dt
    v = np.column_stack([np.sin(t), np.cos(2 * t), 0.1 * np.sin(3 * t)])
    p = np.vstack([np.zeros(3), np.cumsum((v[1:] + v[:-1]) / 2 * dt, axis=0)])
    p[:, 2] += 1.0
    if drift is not None:
        a, b, rate = drift
        p[a:b, 0] += rate * (t[a:b] - t[a])
        p[b:, 0] += rate * (t[b - 1] - t[a])
    p[:20, 2] = 0.05                               # resting on the floor, then takeoff
    cols = ["x", "y", "z", "vx", "vy", "vz", "is_armed", "is_flying"] + INPUTS
    data = np.column_stack([p, v, np.ones(n), np.ones(n), np.full((n, 4), 1500.0)])
    return Dataset(t=t, columns=cols, data=data)


def test_exclusion_rules_on_synthetic_flights():
    drop, spans = flight_exclusions(_flight())
    assert [s["reason"] for s in spans] == ["ground contact"] and drop[:20].all()
    assert not drop[20:].any()
    # a drift of 1 m/s for 0.8 s is a diverging estimate; for 0.2 s it is a transient
    drop, spans = flight_exclusions(_flight(drift=(300, 380, 1.0)))
    assert any(s["reason"] == "diverging state estimate" for s in spans)
    assert drop[300:380].all() and not drop[450:].any()
    drop, spans = flight_exclusions(_flight(drift=(300, 320, 1.0)))
    assert not drop[20:].any()
    glitch = _flight()
    glitch.data[200, glitch.columns.index("w3")] = 33000.0       # a telemetry glitch
    drop, spans = flight_exclusions(glitch)
    assert np.flatnonzero(drop[20:]).tolist() == [180]
    assert spans[-1]["reason"] == "implausible motor speed"


def test_a_flight_without_a_floor_keeps_its_lowest_stretch():
    # cut to the airborne part (no takeoff or landing): the lowest height is flight, not floor
    fl = _flight()
    air = Dataset(t=fl.t[100:500], columns=fl.columns, data=fl.data[100:500])
    z = air.column("z")
    low = np.flatnonzero(z < z.min() + 0.05)
    assert low.size > 10 and 0 < low[0] and low[-1] < len(z) - 1   # a low stretch mid-flight
    drop, spans = flight_exclusions(air)
    assert not drop.any() and spans == []


@real
def test_a_processed_flight_without_time_or_flags_is_read(tmp_path):
    # the airborne middle of a flight, written without t and the status flags (as a processed
    # benchmark file may be): read at the benchmark's 100 Hz, nothing left out for ground
    # contact, every value the raw column's
    raw = pd.read_parquet(SQUARE)
    ds = load_nanodrone(SQUARE)
    a, b = np.searchsorted(raw["t"], ds.t[0] + 3.0), np.searchsorted(raw["t"], ds.t[-1] - 3.0)
    cut = raw.iloc[a:b].drop(columns=["t"] + [c for c in raw.columns if c.startswith("is_")])
    z = cut["z"].to_numpy()
    assert z[0] > z.min() + 0.05 and z[-1] > z.min() + 0.05       # no floor in the cut
    cut.to_parquet(tmp_path / "square_cut.parquet")
    got = load_nanodrone(tmp_path / "square_cut.parquet")
    assert "no column t" in got.meta["time"] and "no status flags" in got.meta["flags"]
    assert got.meta["trajectory"] == "square"
    reasons = {e["reason"] for e in got.meta["excluded"]}
    assert reasons <= {"NaN motor speed", "implausible motor speed"}
    motors = cut[[f"m{k}_erpm" for k in range(1, 5)]].to_numpy()
    ok = ~np.isnan(motors).any(axis=1)
    assert len(got) == ok.sum()
    np.testing.assert_array_equal(got.t, np.flatnonzero(ok) / 100.0)
    for c in ("x", "qw", "wz"):
        np.testing.assert_array_equal(got.column(c), cut[c].to_numpy()[ok])
    np.testing.assert_allclose(got.column("w2"), motors[ok, 1] * np.pi / 180, rtol=1e-15)
    (tmp_path / "bad.parquet").write_bytes(b"PAR1 not a parquet file")
    with pytest.raises(ValueError, match=r"bad\.parquet: corrupt or unreadable Parquet"):
        load_nanodrone(tmp_path / "bad.parquet")
    cut.drop(columns=["qw"]).to_parquet(tmp_path / "noqw.parquet")
    with pytest.raises(ValueError, match=r"noqw\.parquet: .*qw"):
        load_nanodrone(tmp_path / "noqw.parquet")


def _csv(path, n, seed):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, (n, 2))
    y = np.zeros((n, 2))
    for t in range(1, n):
        y[t] = [0.8 * y[t - 1, 0] + 0.3 * u[t - 1, 0], 0.5 * y[t - 1, 1] - 0.2 * u[t - 1, 1]]
    y += 0.01 * rng.standard_normal((n, 2))
    write_dataset(path, Dataset(t=np.arange(n) * 0.01, columns=["u1", "u2", "y1", "y2"],
                                data=np.column_stack([u, y]),
                                meta={"inputs": ["u1", "u2"], "outputs": ["y1", "y2"]}))
    return u, y


def test_several_records_are_segments_nothing_crosses_a_seam(tmp_path):
    u1, y1 = _csv(tmp_path / "a.csv", 200, 0)
    u2, y2 = _csv(tmp_path / "b.parquet", 150, 1)
    st = stack_records([tmp_path / "a.csv", tmp_path / "b.parquet"])
    assert st.lengths == [200, 150] and st.inputs == ["u1", "u2"]
    m = ArxModel((1, 1, 1)).fit(st.U, st.Y, segments=st.lengths)
    # least squares on the per-record regressors, stacked (numpy, independent)
    R = np.vstack([np.c_[y[:-1], u[:-1], np.ones(len(y) - 1)] for u, y in ((u1, y1), (u2, y2))])
    T = np.vstack([y1[1:], y2[1:]])
    want = np.linalg.lstsq(R, T, rcond=None)[0]
    np.testing.assert_allclose(m.coef_, want, rtol=1e-9, atol=1e-12)
    # a k-step prediction in the second record does not see the first
    P = m.predict(st.U, st.Y, mode="k_step", k=5, segments=st.lengths)
    Y2 = st.Y.copy()
    Y2[:200] += 100.0
    P2 = m.predict(st.U, Y2, mode="k_step", k=5, segments=st.lengths)
    assert np.array_equal(P[200:], P2[200:])
    assert np.array_equal(P[200:205], st.Y[200:205])     # its first t0 + k - 1 rows measured
    with pytest.raises(ValueError, match=r"a\.csv: map: column 'nope' \(for zz\) not in"):
        stack_records([tmp_path / "a.csv"], inputs=["zz"], outputs=["y1"], mapping="zz=nope")
    pd.DataFrame({"t": [0.0, 0.01], "u1": [0.0, 1], "u2": [0.0, 1], "y1": [0.0, 1]}).to_parquet(
        tmp_path / "c.parquet")
    with pytest.raises(ValueError, match=r"c\.parquet: outputs: unknown column 'y2'"):
        stack_records([tmp_path / "a.csv", tmp_path / "c.parquet"])
