"""The grey-box model kind (declared model + effects): estimates on records from plain-numpy
generators written here, predictions against a plain-numpy integrator, the model file round trip
and its checked fields."""
import json

import numpy as np
import pytest

from cdam_core.models import load_model, save_model
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.effects import (ActuatorDelay, Backlash, CoulombFriction,
                                              ExternalForce, HardeningStiffness)

DT = 1e-3


def _axis(n=6000, M=0.5, Fv=2.0, Fc=1.0, load=None, seed=0):
    """Rigid axis M q'' + Fv q' + Fc tanh(q'/1e-3) = u (- gain * load), RK-free fine Euler."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = 5 * np.sin(2 * np.pi * 0.7 * t) + 2 * np.sin(2 * np.pi * 3.1 * t)
    ld = np.zeros(n) if load is None else load
    q = np.zeros(n)
    x = v = 0.0
    for k in range(n - 1):
        for _ in range(20):
            a = (u[k] - ld[k] - Fv * v - Fc * np.tanh(v / 1e-3)) / M
            v += a * DT / 20
            x += v * DT / 20
        q[k + 1] = x
    return u, q + rng.normal(0, 1e-6, n)


def _joint(n=8000, Im=0.02, Dm=0.05, Ks=40.0, Kd=0.05, I=0.1, Dl=0.1, K3=400.0, seed=1):
    """A flexible joint in a horizontal plane (no gravity) with a hardening cable."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = 0.8 * np.sin(2 * np.pi * 0.5 * t) + 0.4 * np.sin(2 * np.pi * 2.3 * t + 1) \
        + 0.2 * np.sin(2 * np.pi * 7.0 * t)
    th, q = np.zeros(n), np.zeros(n)
    a, b, va, vb = 0.0, 0.0, 0.0, 0.0
    for k in range(n - 1):
        for _ in range(20):
            d, dd = a - b, va - vb
            tl = Ks * d + K3 * d ** 3 + Kd * dd
            va += (u[k] - Dm * va - tl) / Im * DT / 20
            vb += (tl - Dl * vb) / I * DT / 20
            a += va * DT / 20
            b += vb * DT / 20
        th[k + 1], q[k + 1] = a, b
    return u, th + rng.normal(0, 1e-7, n), q + rng.normal(0, 1e-7, n)


def test_rigid_axis_estimates_and_sigma():
    u, q = _axis()
    g = GreyBox("rigid_axis", DT, [CoulombFriction("tau")]).fit(u[:, None], q[:, None])
    p = g.parameters()
    assert abs(p["M"][0] / 0.5 - 1) < 0.02
    assert abs(p["Fv"][0] / 2.0 - 1) < 0.02
    assert abs(p["coulomb_friction@tau.Fc"][0] / 1.0 - 1) < 0.03
    assert abs(p["offset"][0]) < 5 * p["offset"][1]
    assert all(s is not None and s > 0 for _, s in p.values())


def test_free_run_equals_a_numpy_integrator():
    u, q = _axis(n=3000)
    g = GreyBox("rigid_axis", DT, [CoulombFriction("tau")]).fit(u[:, None], q[:, None])
    th = {k: v for k, (v, _) in g.parameters().items()}
    P = g.predict(u[:, None], q[:, None], mode="free_run")[:, 0]
    # semi-implicit Euler from the state of row 1 (position, backward difference)
    h = DT / g.substeps_
    x, v = q[1], (q[1] - q[0]) / DT
    ref = q.copy()
    for k in range(1, len(q) - 1):
        for _ in range(g.substeps_):
            a = (u[k] - th["Fv"] * v - th["offset"] - th["G"] * np.sin(x) - th["Gc"] * np.cos(x)
                 - th["coulomb_friction@tau.Fc"] * np.sign(v)) / th["M"]
            v += h * a
            x += h * v
        ref[k + 1] = x
    np.testing.assert_allclose(P, ref, rtol=1e-9, atol=1e-12)
    # and it follows the measured axis (the model is right)
    assert np.sqrt(np.mean((P - q) ** 2)) < 0.02 * np.std(q)


def test_k_step_spans_one_step_to_free_run():
    u, q = _axis(n=1500)
    U, Y = u[:, None], q[:, None]
    g = GreyBox("rigid_axis", DT, [CoulombFriction("tau")]).fit(U, Y)
    np.testing.assert_array_equal(g.predict(U, Y, "k_step", k=1), g.predict(U, Y, "one_step"))
    # the last row of a (N - 2)-step prediction is the free run's last row
    np.testing.assert_allclose(g.predict(U, Y, "k_step", k=len(q) - 2)[-1],
                               g.predict(U, Y, "free_run")[-1], rtol=0, atol=1e-12)
    P = g.predict(U, Y, "free_run", segments=[700, 800])
    np.testing.assert_array_equal(P[700:702], Y[700:702])   # each segment restarts from its rows


def test_flexible_joint_hardening_spring():
    u, th, q = _joint()
    U, Y = u[:, None], np.column_stack([th, q])
    g = GreyBox("flexible_joint", DT, [HardeningStiffness("tau_l")],
                fixed={"G": 0.0}).fit(U, Y)
    p = {k: v for k, (v, _) in g.parameters().items()}
    for name, true in (("Im", 0.02), ("Ks", 40.0), ("I", 0.1)):
        assert abs(p[name] / true - 1) < 0.05, (name, p[name])
    assert abs(p["hardening_stiffness@tau_l.K3"] / 400 - 1) < 0.1
    P = g.predict(U, Y, "k_step", k=50)
    assert np.sqrt(np.mean((P[:, 1] - q) ** 2)) < 0.05 * np.std(q)


def _quad(n=1500, dt=0.01, m=1.0, J=(0.02, 0.025, 0.04), K=0.1, Kr=0.01):
    """A quadrotor record from plain numpy: attitude chosen, torques by inverse dynamics (the
    model's rigid-body equations), thrust holding the height, X and Y integrated forward."""
    t = np.arange(n) * dt
    ang = np.column_stack([0.1 * np.sin(2 * np.pi * 0.7 * t), 0.1 * np.sin(2 * np.pi * 0.5 * t + 1),
                           0.3 * np.sin(2 * np.pi * 0.2 * t)])
    d = np.gradient(ang, dt, axis=0)
    dd = np.gradient(d, dt, axis=0)
    pd, td, yd = d.T
    Jx, Jy, Jz = J
    tau = np.column_stack([Jx * dd[:, 0] + (Jz - Jy) * td * yd + Kr * pd,
                           Jy * dd[:, 1] + (Jx - Jz) * pd * yd + Kr * td,
                           Jz * dd[:, 2] + (Jy - Jx) * pd * td + Kr * yd])
    cf, sf, ct, st = np.cos(ang[:, 0]), np.sin(ang[:, 0]), np.cos(ang[:, 1]), np.sin(ang[:, 1])
    cp, sp = np.cos(ang[:, 2]), np.sin(ang[:, 2])
    ux, uy, uz = cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct
    Z = 1.0 + 0.2 * np.sin(2 * np.pi * 0.3 * t)
    Zd = np.gradient(Z, dt)
    T = (m * (np.gradient(Zd, dt) + 9.81) + K * Zd) / uz
    X, Y = np.zeros(n), np.zeros(n)
    vx = vy = 0.0
    for k in range(n - 1):
        vx += dt * (T[k] * ux[k] - K * vx) / m
        vy += dt * (T[k] * uy[k] - K * vy) / m
        X[k + 1], Y[k + 1] = X[k] + dt * vx, Y[k] + dt * vy
    return np.column_stack([T, tau]), np.column_stack([ang, X, Y, Z])


def _variants():
    u, q = _axis(n=2500)
    load = 0.5 * np.sin(np.arange(2500) * DT * 2 * np.pi * 1.3)
    u2, q2 = _axis(n=2500, load=load)
    uj, th, qj = _joint(n=3000)
    Uq, Yq = _quad()
    return {
        "axis_coulomb": (GreyBox("rigid_axis", DT, [CoulombFriction("tau")]), u[:, None], q[:, None]),
        "axis_external": (GreyBox("rigid_axis", DT, [ExternalForce("tau", column="load")],
                                  extra_columns=["load"]),
                          np.column_stack([u2, load]), q2[:, None]),
        "joint_backlash": (GreyBox("flexible_joint", DT, [Backlash("tau_l", width=1e-3),
                                                          HardeningStiffness("tau_l")]),
                           uj[:, None], np.column_stack([th, qj])),
        "quad_delay": (GreyBox("quadrotor", 0.01, [ActuatorDelay(
            "rotors", delay=0.02, channels=("T", "tau_phi", "tau_theta", "tau_psi"))],
            fixed={"m": 1.0}), Uq, Yq),
    }


@pytest.mark.parametrize("name", list(_variants()))
def test_round_trip_every_mode(tmp_path, name):
    g, U, Y = _variants()[name]
    g.fit(U, Y)
    path = tmp_path / "g.json"
    save_model(path, g)
    h = load_model(path)
    assert h.parameters() == g.parameters()
    for mode, k in (("one_step", 1), ("k_step", 7)):
        np.testing.assert_allclose(h.predict(U, Y, mode, k), g.predict(U, Y, mode, k),
                                   rtol=1e-12, atol=1e-12)
    if name != "quad_delay":   # a quadrotor flies closed loop: its 15 s free run only drifts
        np.testing.assert_allclose(h.predict(U, Y, "free_run"), g.predict(U, Y, "free_run"),
                                   rtol=1e-12, atol=1e-12)


def _doc(tmp_path):
    g, U, Y = _variants()["joint_backlash"]
    g.fit(U, Y)
    path = tmp_path / "g.json"
    save_model(path, g)
    return path, json.loads(path.read_text())


def _rewrite(path, doc):
    import hashlib
    body = {k: v for k, v in doc.items() if k != "checksum"}
    doc["checksum"] = {"sha256": hashlib.sha256(json.dumps(
        body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()}
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize("mutate, field", [
    (lambda m: m["effects"][0].__setitem__("name", "magic"), "model.effects[0].name"),
    (lambda m: m["effects"][0].__setitem__("width", "wide"), "model.effects[0].width"),
    (lambda m: m["effects"][0].__setitem__("shell", 1), "model.effects[0].shell"),
    (lambda m: m["parameters"]["names"].__setitem__(0, "Zz"), "model.parameters.names"),
    (lambda m: m["parameters"]["values"].pop(), "model.parameters"),
    (lambda m: m.__setitem__("declared", "rocket"), "model.declared"),
    (lambda m: m.__setitem__("dt", -1), "model.dt"),
    (lambda m: m.__setitem__("substeps", 0), "model.substeps"),
    (lambda m: m["effects"][0].__setitem__("channel", "tau_m\nsystem"), "model.effects[0].channel"),
])
def test_bad_fields_are_named(tmp_path, mutate, field):
    path, doc = _doc(tmp_path)
    mutate(doc["model"])
    _rewrite(path, doc)
    with pytest.raises(ValueError) as err:
        load_model(path)
    assert field in str(err.value)


def test_effect_that_does_not_apply_is_refused():
    with pytest.raises(ValueError, match="does not apply"):
        GreyBox("rigid_axis", DT, [Backlash("tau")]).fit(np.zeros((100, 1)), np.zeros((100, 1)))
