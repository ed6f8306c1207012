"""Clock offset by cross-correlation on synthetic records with a known offset."""
import numpy as np
import pytest
from scipy import signal

from cdam_core.cli.main import main
from cdam_core.record.dataset import Dataset, read_dataset, write_dataset
from cdam_core.record.merge import estimate_offset, merge_records

TRUE_OFFSET = 3.21737   # joints time + offset = flight time


def _motion(seed=0, span=80.0):
    """A smooth random motion s(t) on [0, span] (band-limited noise, closed under np.interp)."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0, span, 1e-3)
    sos = signal.butter(4, 2.0, fs=1000.0, output="sos")
    s = signal.sosfiltfilt(sos, rng.standard_normal(tf.size)) * 30
    return lambda t: np.interp(t, tf, s)


def _records(seed=0, gain=0.5, noise=0.02):
    rng = np.random.default_rng(seed + 100)
    s = _motion(seed)
    tf = 5.0 + np.arange(0, 60.0, 1 / 200.0)                      # flight clock, 200 Hz
    tj = 0.5 + np.arange(0, 60.0, 1e-3) + rng.uniform(0, 2e-4, 60000)   # joints, jittered 1 kHz
    tj.sort()
    flight = Dataset(t=tf, columns=["phi", "T"],
                     data=np.column_stack([s(tf) + noise * rng.standard_normal(tf.size),
                                           np.sin(tf)]),
                     meta={"source": "synthetic flight", "interpolation": {"T": "hold"}})
    joints = Dataset(t=tj, columns=["theta_m1", "tau_m1", "T"],
                     data=np.column_stack([gain * s(tj + TRUE_OFFSET)
                                           + noise * rng.standard_normal(tj.size),
                                           np.cos(tj), np.ones(tj.size)]),
                     meta={"source": "synthetic joints"})
    return flight, joints


@pytest.mark.parametrize("seed, gain", [(0, 0.5), (1, -2.0), (2, 1.0)])
def test_offset_within_stated_uncertainty(seed, gain):
    flight, joints = _records(seed, gain)
    est = estimate_offset(flight.t, flight.column("phi"), joints.t, joints.column("theta_m1"))
    assert abs(est.offset - TRUE_OFFSET) <= 3 * est.uncertainty
    assert est.uncertainty < 2e-3               # a fraction of the 5 ms flight step
    assert np.sign(est.correlation) == np.sign(gain) and abs(est.correlation) > 0.9
    assert len(est.segments) == 8


def test_estimate_rejects_bad_input():
    t = np.arange(1000) / 100.0
    with pytest.raises(ValueError, match="x_a: contains NaN"):
        estimate_offset(t, np.r_[np.nan, t[1:]], t, t)
    with pytest.raises(ValueError, match="t_b: not strictly increasing"):
        estimate_offset(t, t, t[::-1], t)
    with pytest.raises(ValueError, match="constant"):
        estimate_offset(t, np.ones(1000), t, np.sin(t))
    with pytest.raises(ValueError, match="x_b: expected shape"):
        estimate_offset(t, t, t, t[:50])
    with pytest.raises(ValueError, match="too short"):
        estimate_offset(t[:10], t[:10], t[:10], t[:10])


def test_merge_records_aligns_and_renames():
    flight, joints = _records()
    ds, est = merge_records(flight, joints, pair=("phi", "theta_m1"), rate=100.0)
    assert ds.columns == ["phi", "T", "theta_m1", "tau_m1", "T_joints"]
    assert ds.rate == 100.0 and ds.meta["clock_offset"]["pair"] == ["phi", "theta_m1"]
    # grid inside both records once aligned
    assert ds.t[0] >= max(flight.t[0], joints.t[0] + est.offset) - 1e-12
    assert ds.t[-1] <= min(flight.t[-1], joints.t[-1] + est.offset) + 1e-12
    # tau_m1 = cos(joints time) = cos(t - offset): true offset gives the reference
    np.testing.assert_allclose(ds.column("tau_m1"), np.cos(ds.t - TRUE_OFFSET), atol=5e-3)
    # flight T declared zero-order hold: values are exact samples of sin on the 200 Hz grid
    idx = np.searchsorted(flight.t, ds.t, side="right") - 1
    np.testing.assert_array_equal(ds.column("T"), np.sin(flight.t[idx]))
    assert ds.meta["interpolation"]["T"] == "hold"


def test_merge_default_pair_and_errors():
    flight, joints = _records()
    with pytest.raises(ValueError, match="constant"):       # shared name "T": constant in joints
        merge_records(flight, joints)
    j2 = Dataset(t=joints.t, columns=["x"], data=joints.column("theta_m1"))
    with pytest.raises(ValueError, match="share no column"):
        merge_records(flight, j2)
    with pytest.raises(ValueError, match="unknown column 'nope'"):
        merge_records(flight, joints, pair=("phi", "nope"))


def test_merge_cli(tmp_path, capsys):
    flight, joints = _records(seed=3)
    fp, jp, out = tmp_path / "flight.csv", tmp_path / "joints.csv", tmp_path / "record.csv"
    write_dataset(fp, flight)
    write_dataset(jp, joints)
    assert main(["merge", str(fp), str(jp), "-o", str(out), "--pair", "phi:theta_m1"]) == 0
    printed = capsys.readouterr().out
    assert "clock offset" in printed and "+-" in printed
    ds = read_dataset(out)
    off = ds.meta["clock_offset"]
    assert abs(off["offset"] - TRUE_OFFSET) <= 3 * off["uncertainty"]
    assert ds.rate == pytest.approx(200.0)
    assert main(["merge", str(fp), str(jp), "-o", str(out), "--pair", "phi"]) == 2


# -- the shared resampling path (cdam_core.record.resample) ----------------------------------------
def test_resample_kinds_against_independent_formulas():
    from cdam_core.record.resample import find_gaps, resample, uniform_grid
    t = np.array([0.0, 0.1, 0.25, 0.4, 0.7])
    x = np.array([3.0, 2.9, -3.0, -2.9, 3.1])        # wraps across +-pi
    g = uniform_grid(0.0, 0.7, 20.0)
    assert g.size == 15 and g[-1] == pytest.approx(0.7)
    idx = np.searchsorted(t, g, side="right") - 1
    np.testing.assert_array_equal(resample(t, x, g, "hold"), x[idx])
    np.testing.assert_allclose(resample(t, x, g, "linear"), np.interp(g, t, x))
    unwrapped = np.array([3.0, 2.9, -3.0 + 2 * np.pi, -2.9 + 2 * np.pi, 3.1])
    np.testing.assert_allclose(resample(t, x, g, "angle"), np.interp(g, t, unwrapped))
    assert find_gaps(t, 0.2) == [{"start": 0.4, "end": 0.7, "duration": pytest.approx(0.3)}]
    with pytest.raises(ValueError, match="outside the data span"):
        resample(t, x, [0.0, 0.8])
    with pytest.raises(ValueError, match="kind"):
        resample(t, x, g, "cubic")
    with pytest.raises(ValueError, match="x: contains NaN"):
        resample(t, np.r_[x[:4], np.nan], g)
    with pytest.raises(ValueError, match="rate"):
        uniform_grid(0, 1, 0)


def test_a_joints_dropout_stays_a_gap():
    """0.3 s without joint samples: no merged sample inside it (flight time), the joint
    columns elsewhere follow the true signal (cos t of the joints clock), no ramp across."""
    flight, joints = _records(0, 0.5, 0.0)
    lo, hi = 20.0, 20.3                                # joints clock
    keep = (joints.t < lo) | (joints.t > hi)
    joints = Dataset(t=joints.t[keep], columns=joints.columns, data=joints.data[keep],
                     meta=joints.meta)
    merged, est = merge_records(flight, joints, pair=("phi", "theta_m1"))
    gap = (lo + est.offset, hi + est.offset)         # in flight time
    inside = (merged.t > gap[0] + 2e-3) & (merged.t < gap[1] - 2e-3)
    assert not inside.any()
    rows = merged.meta["gapless_rows"]
    assert len(rows) == 2 and rows[0][1] == rows[1][0]
    assert merged.t[rows[1][0]] - merged.t[rows[0][1] - 1] > 0.29
    assert merged.meta["gap_samples"] >= int(0.29 * 200)
    # the tau_m1 column is cos(joints time): checked against the closed form (1 ms jitter
    # steps with linear interpolation: error below 1e-6 rad away from the gap)
    np.testing.assert_allclose(merged.column("tau_m1"), np.cos(merged.t - est.offset),
                               atol=1e-6)


# -- is the alignment meaningful? (issue 22: merge accepted a correlation of -0.013) -----------

def _unrelated(seed):
    """A flight and a joints record whose motions are independent smooth signals."""
    flight, _ = _records(seed)
    _, joints = _records(seed + 500)
    return flight, joints


def test_unrelated_smooth_signals_are_refused_at_the_stated_rate():
    """16 independent pairs: at alpha 0.01 at most one may pass (P(>= 2) < 1.2 %), although
    their peaks (|r| about 0.2) are far beyond what n independent samples allow: the test
    below, on the raw sample count, calls every one of them significant."""
    from scipy import stats
    passed, naive = 0, 0
    for seed in range(16):
        f, j = _unrelated(seed)
        est = estimate_offset(f.t, f.column("phi"), j.t, j.column("theta_m1"))
        passed += est.p_value <= 0.01
        n = 12000 * 0.75                           # most of the 60 s at 200 Hz overlaps
        r = abs(est.correlation)
        naive += 2 * stats.t.sf(r * np.sqrt((n - 2) / (1 - r * r)), n - 2) <= 0.01
    assert passed <= 1
    assert naive >= 14


@pytest.mark.parametrize("noise", [0.02, 2.0])
def test_one_motion_is_accepted_even_noisy(noise):
    flight, joints = _records(seed=4, noise=noise)
    est = estimate_offset(flight.t, flight.column("phi"), joints.t, joints.column("theta_m1"))
    assert est.p_value < 1e-6
    ds, _ = merge_records(flight, joints, pair=("phi", "theta_m1"))
    assert ds.meta["clock_offset"]["significant"] is True


def test_merge_cli_refuses_a_weak_alignment_unless_forced(tmp_path, capsys):
    flight, joints = _unrelated(1)
    fp, jp, out = tmp_path / "flight.csv", tmp_path / "joints.csv", tmp_path / "record.csv"
    write_dataset(fp, flight)
    write_dataset(jp, joints)
    argv = ["merge", str(fp), str(jp), "-o", str(out), "--pair", "phi:theta_m1"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "not significant" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and not out.with_suffix(".json").exists()
    assert main(argv + ["--force", "--json", str(tmp_path / "m.json"),
                        "--report", str(tmp_path / "rep")]) == 0
    cap = capsys.readouterr()
    assert "warning" in cap.err and "warning" not in cap.out
    assert read_dataset(out).meta["clock_offset"]["significant"] is False
    js = __import__("json").loads((tmp_path / "m.json").read_text())
    assert js["clock_offset"]["p_value"] > 0.01
    assert (tmp_path / "rep" / "index.md").is_file()
