"""Simulated flights: determinism, columns, measurement, effects registry, sidecar, CLI."""
import json

import numpy as np
import pytest

pytest.importorskip("cdam_core._core")
from cdam_core.cli.main import main  # noqa: E402
from cdam_core.record.dataset import read_dataset  # noqa: E402
from cdam_core.sim import EFFECTS, parse_effect, simulate_flight  # noqa: E402
from cdam_core.sim.measurement import quantise_motor_angle  # noqa: E402
from cdam_core.sim.parameters import plant_dict, plant_vector, total_mass  # noqa: E402


def test_same_seed_same_record_and_other_seed_differs():
    a = simulate_flight("i", duration=3.0, seed=5)
    b = simulate_flight("i", duration=3.0, seed=5)
    c = simulate_flight("i", duration=3.0, seed=6)
    np.testing.assert_array_equal(a.data, b.data)
    assert not np.allclose(a.data, c.data)
    v = simulate_flight("i", seed=5, validation=True, duration=3.0)
    assert v.meta["record_seed"] != a.meta["record_seed"] and not np.allclose(v.data, a.data)
    assert len(simulate_flight("ii", seed=5, validation=True)) == 10_000


def test_experiments_excite_the_right_channels():
    i = simulate_flight("i", duration=8.0, seed=2)
    ii = simulate_flight("ii", duration=8.0, seed=2)
    assert i.inputs == ["T", "tau_phi", "tau_theta", "tau_psi", "tau_m1", "tau_m2"]
    assert i.outputs == ["phi", "theta", "psi", "X", "Y", "Z", "q1", "q2"]
    # (i): attitude and altitude move, the arm stays near rest; (ii) the other way round
    assert np.std(i.column("psi")) > 0.05 and np.std(i.column("Z")) > 0.03
    assert np.max(np.abs(i.column("q1"))) < 0.1
    assert np.std(ii.column("q1")) > 0.1 and np.std(ii.column("q2")) > 0.1
    assert np.std(ii.column("psi")) < 0.02
    # arm coupling: in (ii) the swinging arm makes the pitch controller work
    assert np.std(ii.column("tau_theta")) > 5 * np.std(ii.column("tau_phi")) + 1e-3


def test_measurement_quantises_motor_angle_to_8192_counts_after_36_to_1():
    ds = simulate_flight("ii", duration=2.0, seed=1)
    lsb = 2 * np.pi / 8192 / 36
    for c in ("theta_m1", "theta_m2"):
        k = ds.column(c) / lsb
        np.testing.assert_allclose(k, np.round(k), atol=1e-6)
    np.testing.assert_allclose(quantise_motor_angle([lsb * 0.49, lsb * 0.51]), [0, lsb])
    step = 0.18 * 0.001       # C610 current step x torque constant
    k = ds.column("tau_m1") / step
    np.testing.assert_allclose(k, np.round(k), atol=1e-6)
    clean = simulate_flight("ii", duration=2.0, seed=1, noise_scale=0.0)
    noise = ds.column("phi") - clean.column("phi")
    assert 0.0015 < np.std(noise) < 0.0025      # 0.002 rad declared


def test_payload_raises_hover_thrust_by_m_g():
    p = plant_dict(plant_vector())
    ds = simulate_flight("ii", duration=6.0, seed=0, effects=["payload_mass:mass=0.2"],
                         noise_scale=0.0)
    ds0 = simulate_flight("ii", duration=6.0, seed=0, noise_scale=0.0)
    # integrators settle: mean thrust over the last 2 s rises by 0.2 g (within the excitation)
    dT = ds.column("T")[-2000:].mean() - ds0.column("T")[-2000:].mean()
    assert dT == pytest.approx(0.2 * p["g"], rel=0.1)
    assert ds0.column("T")[0] == pytest.approx(total_mass(p) * p["g"], rel=1e-12)


def test_thrust_loss_makes_the_logged_thrust_climb():
    c = 0.005
    ds = simulate_flight("ii", duration=10.0, seed=0, effects=[f"thrust_loss:c={c}"], noise_scale=0.0)
    T = ds.column("T")
    ratio = T[-1000:].mean() / T[1000:2000].mean()
    t1, t2 = 9.5, 1.5
    assert ratio == pytest.approx((1 - c * t2) / (1 - c * t1), rel=0.01)


def test_effects_registry_and_parsing():
    assert set(EFFECTS) == {"coulomb_friction", "backlash", "hardening_stiffness", "actuator_delay",
                            "payload_mass", "ground_effect", "thrust_loss", "arm_coupling"}
    name, p = parse_effect("coulomb_friction:Fc1=0.05")
    assert name == "coulomb_friction" and p == {"Fc1": 0.05, "Fc2": 0.02, "eps": 0.05}
    with pytest.raises(ValueError, match="unknown effect"):
        parse_effect("friction")
    with pytest.raises(ValueError, match="unknown parameter 'Fc3'"):
        parse_effect("coulomb_friction:Fc3=1")
    with pytest.raises(ValueError, match="not a number"):
        parse_effect("backlash:width1=wide")
    with pytest.raises(ValueError, match=">= 0"):
        parse_effect("backlash:width1=-1")
    with pytest.raises(ValueError, match="experiment"):
        simulate_flight("iii", duration=1.0)
    with pytest.raises(ValueError, match="seed"):
        simulate_flight("i", duration=1.0, seed=-1)
    with pytest.raises(ValueError, match="duration"):
        simulate_flight("i", duration=float("nan"))
    with pytest.raises(ValueError, match="declare"):
        simulate_flight("i", duration=1.0, declare=["nope"])


def test_sidecar_declares_only_what_is_asked(tmp_path):
    out = tmp_path / "f.csv"
    rc = main(["simulate", "--experiment", "ii", "--duration", "1", "--seed", "4", "--effect",
               "backlash:width1=0.03", "--effect", "actuator_delay", "--declare", "backlash",
               "-o", str(out)])
    assert rc == 0
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["seed"] == 4 and meta["rate"] == 1000.0
    assert meta["effects"]["backlash"] == {"width1": 0.03, "width2": 0.02}
    assert meta["model"]["effects"] == ["backlash"]
    assert meta["undeclared_effects"] == ["actuator_delay", "arm_coupling"]
    assert meta["parameters"]["plant"]["backlash1"] == 0.03
    assert meta["parameters"]["control"]["delay_joint"] == 10.0
    ds = read_dataset(out)
    assert len(ds) == 1000 and ds.columns[:6] == ["T", "tau_phi", "tau_theta", "tau_psi",
                                                  "tau_m1", "tau_m2"]


def test_cli_errors_and_list(tmp_path, capsys):
    assert main(["simulate", "--list-effects"]) == 0
    text = capsys.readouterr().out
    for name in EFFECTS:
        assert name in text
    assert main(["simulate", "--effect", "nope", "-o", str(tmp_path / "x.csv")]) == 2
    assert "unknown effect 'nope'" in capsys.readouterr().err
    assert main(["simulate", "--duration", "1"]) == 2
    assert main(["simulate", "-o", str(tmp_path / "x.txt")]) == 2
