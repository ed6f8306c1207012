"""Model files of every dynamic kind for the firmware tests (no shared data needed), and plain
numpy float32 twins of the firmware's step written from the equations (docs/MODEL_FILE.md, the
module docs of cdam_core.models.arx and greybox.augmented), not from the exporter."""
from __future__ import annotations

import re

import numpy as np

from cdam_core.models import ArxModel
from cdam_core.models.file import save_model
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.hybrid import HybridNarx

F32 = np.float32


def _held(rng, n, cols, lo, hi, hold=10):
    return np.repeat(rng.uniform(lo, hi, (n // hold + 1, cols)), hold, axis=0)[:n]


def arx_file(path, physics=False):
    """A stable two-output ARX(2, 2, 1) fitted on a simulated record (raw features), or an
    ARX(1, 2, 1) on the physics features of four motor commands."""
    rng = np.random.default_rng(0)
    n = 2000
    if physics:
        U = _held(rng, n, 4, 0.2, 1.0) * np.array([400.0, 410.0, 390.0, 405.0])
        Y = np.zeros((n, 1))
        for t in range(1, n):
            Y[t, 0] = 0.8 * Y[t - 1, 0] + 1e-6 * np.sum(U[t - 1] ** 2)
        model, names = ArxModel((1, 2, 1), features="physics"), ["m1", "m2", "m3", "m4"]
    else:
        U = _held(rng, n, 2, -1.0, 1.0)
        Y = np.zeros((n, 2))
        for t in range(2, n):
            Y[t, 0] = 1.2 * Y[t - 1, 0] - 0.5 * Y[t - 2, 0] + 0.4 * U[t - 1, 0] + 0.05
            Y[t, 1] = 0.7 * Y[t - 1, 1] + 0.1 * Y[t - 1, 0] + 0.3 * U[t - 1, 1] - 0.2 * U[t - 2, 0]
        model, names = ArxModel((2, 2, 1)), ["u1", "u2"]
    Y = Y + 1e-3 * rng.standard_normal(Y.shape)
    save_model(path, model.fit(U, Y), inputs=names,
               outputs=[f"y{k}" for k in range(Y.shape[1])])
    return path


def hybrid_file(path):
    """HybridNarx((2, 2, 0)) on a record with a tanh and a square the ARX part misses."""
    rng = np.random.default_rng(1)
    n = 2000
    u = _held(rng, n, 2, -1.0, 1.0)
    y = np.zeros((n, 2))
    for t in range(2, n):
        y[t, 0] = 0.6 * y[t - 1, 0] - 0.1 * y[t - 2, 0] + 0.5 * np.tanh(2 * u[t - 1, 0])
        y[t, 1] = 0.7 * y[t - 1, 1] + 0.2 * y[t - 1, 0] + 0.3 * u[t, 1] ** 2
    y = y + 1e-3 * rng.standard_normal(y.shape)
    h = HybridNarx((2, 2, 0), seed=1).fit(u, y)
    save_model(path, h, inputs=["u1", "u2"], outputs=["y1", "y2"])
    return path, h


RIGID = {"M": 95.0, "Fv": 240.0, "offset": -0.25, "Fc": 20.0, "dFv": -70.0, "gain": 0.5,
         "delay": 0.0035, "dt": 0.001, "substeps": 3}


def greybox_file(path, effects=("coulomb", "asymmetric", "external", "delay"), meta=None,
                 inputs=("tau", "load"), outputs=("q",), extra_column="load"):
    """A rigid_axis grey-box model with the numbers of RIGID and the chosen effects."""
    p = RIGID
    names, values = ["M", "Fv", "offset"], [p["M"], p["Fv"], p["offset"]]
    eff = []
    if "coulomb" in effects:
        eff.append({"name": "coulomb_friction", "channel": "tau", "eps": 0.0, "smooth": False})
        names.append("coulomb_friction@tau.Fc")
        values.append(p["Fc"])
    if "asymmetric" in effects:
        eff.append({"name": "asymmetric_friction", "channel": "tau"})
        names.append("asymmetric_friction@tau.dFv")
        values.append(p["dFv"])
    extra = []
    if "external" in effects:
        extra = [extra_column]
        eff.append({"name": "external_force", "channel": "tau", "column": extra_column})
        names.append(f"external_force[{extra_column}]@tau.gain")
        values.append(p["gain"])
    if "delay" in effects:
        eff.append({"name": "actuator_delay", "channel": "tau", "delay": p["delay"]})
    d = {"declared": "rigid_axis", "dt": p["dt"], "n_inputs": 1 + len(extra), "n_outputs": 1,
         "fixed": {}, "extra_columns": extra, "filter": {"cutoff_hz": 100.0, "order": 4},
         "effects": eff, "parameters": {"names": names, "values": values,
                                        "std": [None] * len(names), "estimated": names},
         "substeps": p["substeps"]}
    g = GreyBox.from_dict(d)
    save_model(path, g, inputs=list(inputs)[:1 + len(extra)], outputs=list(outputs), meta=meta)
    return path


PENDULUM = {"M": 0.5, "Fv": 2.0, "offset": 0.05, "G": 1.5, "Gc": 0.44, "Fc": 1.0, "dt": 0.001}


def pendulum_file(path):
    """A rotary rigid_axis in a vertical plane: gravity G sin q + Gc cos q (an encoder whose
    zero is 0.29 rad off the hanging position), a torque offset and smoothed dry friction."""
    p = PENDULUM
    names = ["M", "Fv", "offset", "G", "Gc", "coulomb_friction@tau.Fc"]
    d = {"declared": "rigid_axis", "dt": p["dt"], "n_inputs": 1, "n_outputs": 1, "fixed": {},
         "extra_columns": [], "filter": {"cutoff_hz": 50.0, "order": 4},
         "effects": [{"name": "coulomb_friction", "channel": "tau", "eps": 0.01,
                      "smooth": True}],
         "parameters": {"names": names, "values": [p[k.split(".")[-1]] for k in names],
                        "std": [None] * len(names), "estimated": names},
         "substeps": 2}
    save_model(path, GreyBox.from_dict(d), inputs=["tau"], outputs=["q"])
    return path


def rigid_record(n=600, seed=2, extra=True):
    """Force (and load) held random levels beyond the friction; positions from the model."""
    rng = np.random.default_rng(seed)
    U = _held(rng, n, 2 if extra else 1, -60.0, 60.0, hold=40)
    return U


# ---- float32 twins: one operation after the other, as the equations are written ----

def arx_twin32(coef, na, nb, nk, U, Y, mode, scale=None):
    """ARX in float32: y(t) = sum A y(t-j) + (sum B f(t-nk-j) + c), features raw or physics."""
    coef = np.asarray(coef, dtype=F32)
    m = coef.shape[1]
    if scale is not None:
        u = U.astype(F32) / np.asarray(scale, F32)
        q = u * u
        F = np.column_stack([u, ((q[:, 0] + q[:, 1]) + q[:, 2]) + q[:, 3],
                             ((q[:, 0] + q[:, 3]) - q[:, 1]) - q[:, 2],
                             ((q[:, 0] + q[:, 1]) - q[:, 2]) - q[:, 3],
                             ((q[:, 0] - q[:, 1]) + q[:, 2]) - q[:, 3]]).astype(F32)
    else:
        F = U.astype(F32)
    nf = F.shape[1]
    t0 = max(na, nk + nb - 1)
    P = Y.astype(F32).copy()
    out = []
    for t in range(t0, len(U)):
        y = np.zeros(m, F32)
        for o in range(m):
            past = F32(0)
            for j in range(na):
                for c in range(m):
                    past = F32(past + F32(P[t - 1 - j, c] * coef[j * m + c, o]))
            term = F32(0)
            for j in range(nb):
                for c in range(nf):
                    term = F32(term + F32(F[t - nk - j, c] * coef[na * m + j * nf + c, o]))
            term = F32(term + F32(F32(1) * coef[-1, o]))
            y[o] = F32(past + term)
        out.append(y)
        if mode == "free_run":
            P[t] = y
    return np.array(out)


def rigid_twin32(p, U, Y, mode, inertia=None):
    """rigid_axis + Coulomb + asymmetric friction + external force + actuator delay in float32:
    r = tau_d - Fv v - offset - Fc sign(v) - dFv v [v > 0] - gain (-load),  a = r / M,
    substeps of v += h a, x += h v; tau_d = tau(t - delay) interpolated linearly (np.interp,
    held at the first sample before the start). ``inertia``: the 1/M to use (float64)."""
    dt, sub = p["dt"], p["substeps"]
    h = F32(dt / sub)
    inv = F32(1.0 / p["M"] if inertia is None else inertia)
    n = len(U)
    # the firmware interpolates in float32 on the float32 inputs: lag L, fraction as exported
    L = int(np.ceil(p["delay"] / dt)) if p["delay"] else 0
    u32 = U.astype(F32)
    Y32 = Y.astype(F32)
    x, v = Y32[1, 0], F32(F32(Y32[1, 0] - Y32[0, 0]) / F32(dt))
    out = []
    for k in range(1, n - 1):          # state at row k -> row k + 1
        if mode == "one_step":
            x, v = Y32[k, 0], F32(F32(Y32[k, 0] - Y32[k - 1, 0]) / F32(dt))
        if L:
            if k < L:
                td = u32[0, 0]
            else:
                lo, hi = u32[k - L, 0], u32[k - L + 1, 0]
                td = F32(F32(F32(F32(hi - lo) / F32(dt)) * F32(L * dt - p["delay"])) + lo)
        else:
            td = u32[k, 0]
        for _ in range(sub):
            r = td
            r = F32(r - F32(F32(p["Fv"]) * v))
            r = F32(r - F32(F32(p["offset"]) * F32(1)))
            r = F32(r - F32(F32(p["Fc"]) * F32(np.sign(v))))
            pos = F32(1) if v > 0 else F32(0)
            r = F32(r - F32(F32(p["dFv"]) * F32(v * pos)))
            if U.shape[1] > 1:
                r = F32(r - F32(F32(p["gain"]) * F32(-u32[k, 1])))
            a = F32(F32(0) + F32(inv * r))
            v = F32(v + F32(h * a))
            x = F32(x + F32(h * v))
        out.append(x)
    return np.array(out, dtype=F32)[:, None]


FLEX_EFFECTS = [{"name": "backlash", "channel": "tau_l", "width": 0.02},
                {"name": "hardening_stiffness", "channel": "tau_l"},
                {"name": "coulomb_friction", "channel": "tau_m", "eps": 0.01, "smooth": True},
                {"name": "asymmetric_friction", "channel": "tau_l"},
                {"name": "payload_mass", "channel": "tau_l", "length": 0.3},
                {"name": "actuator_delay", "channel": "tau_m", "delay": 0.0025}]


def flexible_file(path):
    """A flexible_joint grey-box model (one cable-driven joint) with every effect the library
    has for it: backlash, a hardening cable, smoothed Coulomb friction on the motor,
    asymmetric friction on the link, a payload and an actuator delay; 4 substeps."""
    names = ["Im", "Dm", "Ks", "Kd", "I", "Dl", "G", "hardening_stiffness@tau_l.K3",
             "coulomb_friction@tau_m.Fc", "asymmetric_friction@tau_l.dFv",
             "asymmetric_friction@tau_l.dFc", "payload_mass@tau_l.m"]
    values = [0.01, 0.1, 20.0, 0.05, 0.02, 0.05, 0.5, 300.0, 0.05, 0.01, 0.02, 0.2]
    d = {"declared": "flexible_joint", "dt": 0.001, "n_inputs": 1, "n_outputs": 2,
         "fixed": {"I": 0.02, "G": 0.5}, "extra_columns": [],
         "filter": {"cutoff_hz": 100.0, "order": 4}, "effects": FLEX_EFFECTS,
         "parameters": {"names": names, "values": values, "std": [None] * len(names),
                        "estimated": [n for n in names if n not in ("I", "G")]},
         "substeps": 4}
    save_model(path, GreyBox.from_dict(d), inputs=["tau_m1"], outputs=["theta_m1", "q1"])
    return path


QUAD = {"names": ["m", "Kx", "Ky", "Kz", "Jx", "Jy", "Jz", "Kphi", "Ktheta", "Kpsi",
                  "ground_effect@Z.k", "thrust_loss@Z.c", "payload_mass@Z.mass"],
        "values": [1.8, 0.2, 0.2, 0.3, 0.02, 0.02, 0.04, 0.01, 0.01, 0.02, 1.0, 0.003, 0.2]}


def quadrotor_file(path):
    """A quadrotor grey-box model (flight.Quadrotor, dt 10 ms, 2 substeps) with the rotors'
    shared delay, ground effect, thrust loss and a payload on Z."""
    eff = [{"name": "actuator_delay", "channel": "rotors",
            "channels": ["T", "tau_phi", "tau_theta", "tau_psi"], "delay": 0.025},
           {"name": "ground_effect", "channel": "Z"}, {"name": "thrust_loss", "channel": "Z"},
           {"name": "payload_mass", "channel": "Z"}]
    d = {"declared": "quadrotor", "dt": 0.01, "n_inputs": 4, "n_outputs": 6,
         "fixed": {"m": 1.8}, "extra_columns": [], "filter": {"cutoff_hz": 2.0, "order": 4},
         "effects": eff, "parameters": {"names": QUAD["names"], "values": QUAD["values"],
                                        "std": [None] * 13, "estimated": QUAD["names"][1:]},
         "substeps": 2}
    save_model(path, GreyBox.from_dict(d))
    return path


# the aerial manipulator of the simulator's parameter table (cdam_core.sim.parameters): body
# m, drags, inertias; cables Im, Dm, Ks, Kd; links p1 = I1 + m1 lc1^2 + m2 l1^2,
# p2 = m2 l1 lc2, p3 = I2 + m2 lc2^2, g1 = (m1 lc1 + m2 l1) g, g2 = m2 lc2 g; Dl
AERIAL = {"m": 1.8, "Kx": 0.25, "Ky": 0.25, "Kz": 0.3, "Jx": 0.02, "Jy": 0.02, "Jz": 0.04,
          "Kphi": 0.005, "Ktheta": 0.005, "Kpsi": 0.005,
          "Im1": 1e-3, "Dm1": 2e-3, "Ks1": 20.0, "Kd1": 0.02,
          "Im2": 1e-3, "Dm2": 2e-3, "Ks2": 15.0, "Kd2": 0.02,
          "p1": 4e-4 + 0.12 * 0.1 ** 2 + 0.1 * 0.2 ** 2, "p2": 0.1 * 0.2 * 0.12,
          "p3": 4e-4 + 0.1 * 0.12 ** 2, "g1": (0.12 * 0.1 + 0.1 * 0.2) * 9.81,
          "g2": 0.1 * 0.12 * 9.81, "Dl1": 2e-3, "Dl2": 2e-3}
AERIAL_EFFECTS = [
    {"name": "actuator_delay", "channel": "rotors",
     "channels": ["T", "tau_phi", "tau_theta", "tau_psi"], "delay": 0.0035},
    {"name": "coulomb_friction", "channel": "tau_m1", "eps": 0.05, "smooth": True},
    {"name": "backlash", "channel": "tau_l2", "width": 0.01},
    {"name": "hardening_stiffness", "channel": "tau_l2"},
    {"name": "asymmetric_friction", "channel": "tau_l1"},
    {"name": "payload_mass", "channel": "Z"}]
AERIAL_EFFECT_VALUES = {"coulomb_friction@tau_m1.Fc": 0.01,
                        "hardening_stiffness@tau_l2.K3": 200.0,
                        "asymmetric_friction@tau_l1.dFv": 1e-3,
                        "asymmetric_friction@tau_l1.dFc": 2e-3,
                        "payload_mass@Z.mass": 0.2}


def aerial_file(path, effects=True, dt=0.001):
    """An aerial_manipulator grey-box model (the body and both cable-driven joints) at 1 kHz,
    with a delay on the rotors, smoothed Coulomb friction on motor 1, a backlash and a hardening
    spring in cable 2, asymmetric friction on link 1 and a payload on Z (or none)."""
    from cdam_core.models.greybox.registry import get_model
    m = get_model("aerial_manipulator")
    vals = dict(AERIAL)
    if effects:
        vals.update(AERIAL_EFFECT_VALUES)
    names = list(m.parameter_names) + [k for k in vals if k not in m.parameter_names]
    g = GreyBox.from_dict({
        "declared": "aerial_manipulator", "dt": dt, "n_inputs": 6, "n_outputs": 10,
        "fixed": {"m": AERIAL["m"]}, "extra_columns": [],
        "filter": {"cutoff_hz": 2.0, "order": 4},
        "effects": AERIAL_EFFECTS if effects else [],
        "parameters": {"names": names, "values": [vals[n] for n in names],
                       "std": [None] * len(names), "estimated": names[1:]},
        "substeps": 1})
    g = GreyBox.from_dict({**g.to_dict(), "substeps": g._choose_substeps()})
    save_model(path, g)
    return path


ARM_CHANNELS = ("X", "Y", "Z", "tau_phi", "tau_theta")


def arm_coupling_file(path, monitor=False):
    """The aerial manipulator with arm_coupling on its five channels in the causal form the
    board runs, fitted on a simulated 10 s flight ('both', seed 3, 1 kHz; the simulator's arm
    is always coupled); with ``monitor``, its monitor section calibrated on the first 4 s.
    Returns (path, U, Y) of the flight."""
    from cdam_core.evaluate.monitor import calibrate
    from cdam_core.models.greybox.effects import ArmCoupling
    from cdam_core.models.greybox.registry import get_model
    from cdam_core.sim import simulate_flight
    from cdam_core.sim.parameters import plant_dict, plant_vector, total_mass
    ds = simulate_flight("both", duration=10.0, seed=3, declare=["arm_coupling"])
    m = get_model("aerial_manipulator")
    U = np.column_stack([ds.column(k) for k in m.inputs])
    Y = np.column_stack([ds.column(k) for k in m.positions])
    dt = float(np.median(np.diff(ds.t)))
    g = GreyBox("aerial_manipulator", dt,
                fixed={"m": total_mass(plant_dict(plant_vector()), with_payload=False)},
                effects=[ArmCoupling(c, causal=True) for c in ARM_CHANNELS]).fit(U, Y)
    save_model(path, g, inputs=list(m.inputs), outputs=list(m.positions),
               monitor=calibrate(g, U[:4000], Y[:4000], dt, paths=100, seed=0)
               if monitor else None)
    return path, U, Y


QUAD_LAG = 0.03     # s, the generator's rotor lag and the quad_physics model's stated one
QUAD_N_FIT = 400    # rows of the 6 s flight the quad_physics model is fitted on


def quad_physics_file(path, meta=None):
    """A quad_physics model with every option that costs on the target (a 15-tap actuation
    lag, rate damping, the yaw reaction) fitted on the first 4 s of a 6 s flight of the
    independent generator (tests/models/quad_generator.py, 30 ms rotor lag); returns
    (path, U, Y) of the whole flight (rows QUAD_N_FIT.. are held out)."""
    import sys
    from pathlib import Path
    from cdam_core.models.flight.physics import QuadPhysics
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "models"))
    from quad_generator import flight
    U, Y, _ = flight(seconds=6.0, seed=3, lag=QUAD_LAG)
    m = QuadPhysics(lag=QUAD_LAG, damping=True, reaction=True).fit(U[:QUAD_N_FIT],
                                                                  Y[:QUAD_N_FIT])
    save_model(path, m, inputs=[f"rotor_speed_m{k}" for k in range(1, 5)],
               outputs=[f"state_{k}" for k in range(13)], meta=meta)
    return path, U, Y


QUAD_HYBRID_N_FIT = 600   # rows of the 8 s flight the quad_hybrid model is fitted on


def quad_hybrid_file(path, meta=None, monitor=False):
    """A small quad_hybrid (4 tanh units, 3 rotor lags, 10-step windows, 5 LM epochs) fitted on
    the first 6 s of an 8 s flight of the independent generator with a 30 ms rotor lag the
    physics lacks; with ``monitor``, its monitor section calibrated on those 6 s. Returns
    (path, U, Y) of the whole flight (rows QUAD_HYBRID_N_FIT.. are held out)."""
    import sys
    from pathlib import Path
    from cdam_core.evaluate.monitor import calibrate
    from cdam_core.models.flight.hybrid import QuadHybrid
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "models"))
    from quad_generator import flight
    U, Y, _ = flight(seconds=8.0, seed=3, lag=QUAD_LAG)
    n = QUAD_HYBRID_N_FIT
    m = QuadHybrid(hidden=4, lags=3, horizon=10, epochs=5, threads=1).fit(U[:n], Y[:n])
    save_model(path, m, inputs=[f"rotor_speed_m{k}" for k in range(1, 5)],
               outputs=[f"state_{k}" for k in range(13)], meta=meta,
               monitor=calibrate(m, U[:n], Y[:n], 0.01, paths=200, seed=0) if monitor else None)
    return path, U, Y


def quad_twin32(model, U, Y, mode):
    """quad_physics in float32, written from the model's module doc (one RK4 step of dt per
    sample, drive held; the quaternion normalised before and after), every operation rounded
    to float32 in the order the expressions are written. Rows t0.. of ``mode`` (one_step or
    free_run)."""
    f32 = F32
    d = model.to_dict()
    dt = f32(d["dt"])
    tr = np.asarray(d["translation"], f32)
    ro = np.asarray(d["rotation"], f32)
    g = f32(d["gravity"])
    dT, dR = d["delays"]
    if d["lag"]:
        a = np.exp(-d["dt"] / d["lag"])
        w = (1 - a) * a ** np.arange(int(np.ceil(5 * d["lag"] / d["dt"])))
        w = (w / w.sum()).astype(f32)
    else:
        w = np.ones(1, f32)
    t0 = 1 + (len(w) - 1) + (1 if d["reaction"] else 0) + max(dT, dR)
    u32, y32 = U.astype(f32), Y.astype(f32)
    dynamic = d["rates"] == "dynamic"

    def drive(t, lag):        # sum_j w_j u(t-1-lag-j)^2
        f = np.zeros(4, f32)
        for j in range(len(w)):
            r = u32[t - 1 - lag - j]
            f = (f + w[j] * (r * r)).astype(f32)
        return f

    def unit(x):
        q = x[6:10]
        n = np.sqrt(f32(f32(f32(q[0] * q[0] + q[1] * q[1]) + q[2] * q[2]) + q[3] * q[3]))
        x[6:10] = q / n

    def deriv(x, thrust, acc):
        v, (qx, qy, qz, qw), (wx, wy, wz) = x[3:6], x[6:10], x[10:13]
        n = np.array([f32(2) * (qx * qz + qw * qy), f32(2) * (qy * qz - qw * qx),
                      f32(1) - f32(2) * (qx * qx + qy * qy)], f32)
        nv = f32(f32(n[0] * v[0] + n[1] * v[1]) + n[2] * v[2])
        dx = np.empty(13, f32)
        dx[0:3] = v
        dx[3:6] = (thrust * n - tr[1] * v) - ((tr[2] - tr[1]) * n) * nv
        dx[5] = dx[5] - g
        dx[6] = f32(0.5) * (qw * wx + (qy * wz - qz * wy))
        dx[7] = f32(0.5) * (qw * wy + (qz * wx - qx * wz))
        dx[8] = f32(0.5) * (qw * wz + (qx * wy - qy * wx))
        dx[9] = f32(-0.5) * f32(f32(qx * wx + qy * wy) + qz * wz)
        gyro = np.array([wy * wz, wx * wz, wx * wy], f32)
        dx[10:13] = (acc + ro[3:6] * gyro) - ro[9:12] * x[10:13] if dynamic else 0
        return dx

    half, sixth = f32(f32(0.5) * dt), f32(d["dt"] / 6.0)
    x = y32[t0 - 1].copy()
    out = []
    for t in range(t0, len(U)):
        if mode == "one_step":
            x = y32[t - 1].copy()
        unit(x)
        f = drive(t, dT)
        thrust = tr[0] * f32(f32(f32(f[0] + f[1]) + f[2]) + f[3])
        acc = np.zeros(3, f32)
        if dynamic:
            f = drive(t, dR)
            tau = np.array([f32(f32(-f[0] - f[1]) + f[2]) + f[3],
                            f32(f32(-f[0] + f[1]) + f[2]) - f[3],
                            f32(f32(-f[0] + f[1]) - f[2]) + f[3]], f32)
            acc = ro[0:3] * tau + ro[6:9]
            if d["reaction"]:
                a, b = u32[t - 1 - dR], u32[t - 2 - dR]
                s = f32(f32(f32((a[0] - b[0]) * f32(-1)) + (a[1] - b[1]))
                        + (a[2] - b[2]) * f32(-1)) + (a[3] - b[3])
                acc[2] = acc[2] + ro[12] * f32(s / dt)
        k1 = deriv(x, thrust, acc)
        k2 = deriv(x + half * k1, thrust, acc)
        k3 = deriv(x + half * k2, thrust, acc)
        k4 = deriv(x + dt * k3, thrust, acc)
        x = x + sixth * (((k1 + f32(2) * k2) + f32(2) * k3) + k4)
        unit(x)
        out.append(x.copy())
    return np.array(out, f32)


# ---- reading a generated header, and the nano-drone flights (the flight kinds' tests) ----

def header_array(text, name):
    """The values of ``constexpr float name[n] = {...};`` in a generated header."""
    m = re.search(rf"constexpr float {name}\[(\d+)\] = \{{(.*?)\}};", text, re.S)
    assert m, name
    return np.array([float(v.strip().rstrip("f")) for v in m.group(2).split(",")])


def header_int(text, name):
    """The value of ``constexpr int name = n;`` in a generated header."""
    return int(re.search(rf"constexpr int {name} = (-?\d+);", text).group(1))


def nanodrone_flight(folder, name):
    """(U, Y) of the longest segment of a nano-drone flight (no seam inside)."""
    from cdam_core.record.realdata.nanodrone import INPUTS, STATES, load_nanodrone
    ds = load_nanodrone(folder / f"{name}.parquet")
    a, b = max(ds.segments, key=lambda s: s[1] - s[0])
    return (np.column_stack([ds.column(c) for c in INPUTS])[a:b],
            np.column_stack([ds.column(c) for c in STATES])[a:b])


def assert_float32_overflow_refused(model, tmp_path, array_name):
    """A model whose numbers are finite in the file but not in float32 (set by the caller):
    load_firmware_model names the array, and export-firmware exits 2 writing nothing."""
    import pytest
    from cdam_core import firmware as fw
    from cdam_core.cli.main import main
    save_model(tmp_path / "big.json", model)
    with pytest.raises(ValueError, match=f"{array_name}: not finite in float32"):
        fw.load_firmware_model(tmp_path / "big.json")
    assert main(["export-firmware", str(tmp_path / "big.json"), "-o",
                 str(tmp_path / "m.hpp")]) == 2
    assert not (tmp_path / "m.hpp").exists()


def cli_check_report(path, out, build_dir, kind, hostile):
    """`cdam firmware check MODEL --json OUT` on the default record: exit 0, the report's kind
    and steps (the record's rows after the model's t0), and nothing of the file's text (the
    ``hostile`` string it carries, the inputs' names) in the report. Returns the report."""
    import json

    from cdam_core.cli.main import main
    from cdam_core.models.file import load_model
    assert main(["firmware", "check", str(path), "--json", str(out),
                 "--build-dir", str(build_dir)]) == 0
    rep = json.loads(out.read_text())
    assert rep["kind"] == kind and rep["steps"] == 1000 - load_model(path).t0
    assert hostile not in json.dumps(rep) and "rotor_speed" not in json.dumps(rep)
    return rep
