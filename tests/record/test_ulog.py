"""PX4 ULog import on the three logs in ../shared/data/ulog, checked against pyulog's raw data."""
import json

import numpy as np
import pytest
from pyulog import ULog

import cdam_core.record.ulog as ulog_mod
from cdam_core.cli.main import main
from cdam_core.record.dataset import read_dataset
from cdam_core.record.realdata import shared_data_dir
from cdam_core.record.ulog import load_ulog, quaternion_to_euler_zyx

ULOG_DIR = shared_data_dir() / "ulog"
SITL = ULOG_DIR / "sample_px4_events.ulg"
SMALL = ULOG_DIR / "sample_log_small.ulg"
BENCH = ULOG_DIR / "sample_appended_multiple.ulg"
pytestmark = pytest.mark.skipif(not SITL.is_file(), reason="shared ULog data not found")


def _raw(path, topic):
    d = [d for d in ULog(str(path), [topic]).data_list if d.multi_id == 0][0]
    return d.data


def _euler_closed_form(q):
    w, x, y, z = q.T
    phi = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    theta = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
    psi = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.column_stack([phi, theta, psi])


def test_quaternion_to_euler_matches_closed_form():
    rng = np.random.default_rng(7)
    q = rng.standard_normal((200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    np.testing.assert_allclose(quaternion_to_euler_zyx(q), _euler_closed_form(q), atol=1e-9)
    with pytest.raises(ValueError, match="q: expected shape"):
        quaternion_to_euler_zyx(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="zero quaternion"):
        quaternion_to_euler_zyx(np.zeros((1, 4)))


def test_sitl_log_columns_frames_and_interpolation():
    ds = load_ulog(SITL, rate=200.0)
    m = ds.meta
    assert m["platform"] == "SITL" and m["ver_hw"] == "PX4_SITL"
    assert m["missing"] == []
    assert ds.inputs == ["T", "tau_phi", "tau_theta", "tau_psi"]
    assert ds.outputs == ["phi", "theta", "psi", "X", "Y", "Z"]
    assert [c for c in ds.columns if c.startswith("motor")] == [f"motor{k}" for k in range(1, 5)]
    np.testing.assert_allclose(np.diff(ds.t), 1 / 200.0, atol=1e-9)
    t0 = m["t0_us"]

    # attitude: NED/FRD -> NWU/FLU by conjugating R with Rx(pi), Euler read off the matrix
    att = _raw(SITL, "vehicle_attitude")
    ta = (att["timestamp"] - t0) * 1e-6
    qq = np.column_stack([att[f"q[{k}]"] for k in range(4)]).astype(np.float64)
    w, x, y, z = (qq / np.linalg.norm(qq, axis=1, keepdims=True)).T   # logged as float32
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    F = np.diag([1.0, -1.0, -1.0])
    Rf = np.einsum("ij,jkn,kl->iln", F, R, F)
    euler = np.column_stack([np.arctan2(Rf[2, 1], Rf[2, 2]), -np.arcsin(Rf[2, 0]),
                             np.arctan2(Rf[1, 0], Rf[0, 0])])
    for j, name in enumerate(["phi", "theta", "psi"]):
        exp = np.interp(ds.t, ta, np.unwrap(euler[:, j]))
        np.testing.assert_allclose(ds.column(name), exp, atol=1e-9)

    # position linear, Z up
    pos = _raw(SITL, "vehicle_local_position")
    tp = (pos["timestamp"] - t0) * 1e-6
    np.testing.assert_allclose(ds.column("Z"), np.interp(ds.t, tp, -pos["z"]), atol=1e-9)
    np.testing.assert_allclose(ds.column("Y"), np.interp(ds.t, tp, -pos["y"]), atol=1e-9)
    assert ds.column("Z").max() > 1.5      # the SITL takeoff climbs to about 2.2 m

    # thrust setpoint: zero-order hold of -xyz[2]
    thr = _raw(SITL, "vehicle_thrust_setpoint")
    tt = (thr["timestamp"] - t0) * 1e-6
    idx = np.searchsorted(tt, ds.t, side="right") - 1
    np.testing.assert_array_equal(ds.column("T"), -thr["xyz[2]"][idx])
    assert "normalised" in m["units"]["T"] and m["units"]["phi"] == "rad"
    assert m["interpolation"]["T"] == "hold" and m["interpolation"]["psi"] == "angle"


@pytest.mark.parametrize("path", [SMALL, BENCH])
def test_hardware_logs_use_actuator_controls(path):
    ds = load_ulog(path, rate=100.0)
    m = ds.meta
    assert m["platform"] == "hardware"
    assert m["topics"]["setpoints"] == "actuator_controls_0"
    assert m["topics"]["motors"] == "actuator_outputs" and m["units"]["motor1"] == "PWM (us)"
    ac = _raw(path, "actuator_controls_0")
    ta = (ac["timestamp"] - m["t0_us"]) * 1e-6
    idx = np.searchsorted(ta, ds.t, side="right") - 1
    np.testing.assert_array_equal(ds.column("tau_theta"), -ac["control[1]"][idx])
    np.testing.assert_array_equal(ds.column("T"), ac["control[3]"][idx])


def test_small_log_reports_its_start_gap():
    m = load_ulog(SMALL, rate=100.0).meta
    # every topic of this log waits ~0.16 s after its first sample (independent: pyulog data)
    att = _raw(SMALL, "vehicle_attitude")
    first = np.diff(att["timestamp"][:2])[0] * 1e-6
    assert m["gaps"]["phi"][0]["duration"] == pytest.approx(first)
    assert m["dropouts"] and m["dropouts"][0]["duration"] == pytest.approx(0.03)


def test_missing_topics_give_partial_record(monkeypatch):
    real = ulog_mod._topic

    def without(ulog, name):
        return None if name in ("vehicle_thrust_setpoint", "vehicle_torque_setpoint",
                                "actuator_controls_0", "vehicle_local_position") else real(ulog, name)
    monkeypatch.setattr(ulog_mod, "_topic", without)
    ds = load_ulog(SITL, rate=50.0)
    assert "T" not in ds.columns and "X" not in ds.columns and "phi" in ds.columns
    assert any("setpoints" in s for s in ds.meta["missing"])
    assert any("position" in s for s in ds.meta["missing"])

    monkeypatch.setattr(ulog_mod, "_topic", lambda u, n: None)
    with pytest.raises(ValueError, match="no usable topic"):
        load_ulog(SITL)


def test_bad_inputs(tmp_path):
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"not a ulog file at all" * 10)
    with pytest.raises(ValueError, match="not a readable ULog"):
        load_ulog(bad)
    with pytest.raises(ValueError, match="rate"):
        load_ulog(SITL, rate=0)
    with pytest.raises(FileNotFoundError):
        load_ulog(tmp_path / "none.ulg")


def test_import_ulog_cli_default_rate(tmp_path, capsys):
    out = tmp_path / "flight.csv"
    assert main(["import-ulog", str(SITL), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "SITL log" in printed and "columns T, tau_phi" in printed
    ds = read_dataset(out)
    assert ds.rate == 1000.0
    np.testing.assert_allclose(np.diff(ds.t), 1e-3, atol=1e-9)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["platform"] == "SITL" and "gaps" in side
    assert ds.inputs == ["T", "tau_phi", "tau_theta", "tau_psi"]


def test_import_ulog_cli_reports_gaps(tmp_path, capsys):
    assert main(["import-ulog", str(SMALL), "-o", str(tmp_path / "s.csv"), "--rate", "100"]) == 0
    cap = capsys.readouterr()
    assert "hardware log" in cap.out                       # results on stdout, warnings on stderr
    assert "warning: gap: phi" in cap.err and "dropout" in cap.err
    assert main(["import-ulog", str(tmp_path / "x.ulg"), "-o", str(tmp_path / "s.csv")]) == 2
