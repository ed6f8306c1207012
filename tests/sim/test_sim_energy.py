"""Energy of the unforced, undamped system is conserved (to 1e-6 relative over 10 s).

The energy is computed here from the geometry, independently of the simulator's equations:
kinetic energy of the body, both links (translation + rotation) and both motor sides, the
cable spring energy and the gravitational potential.

Step: RK4 is not symplectic; it dissipates an oscillation by about z^6/72 of its energy per step
(z = h omega). The motor-side cable mode (omega = sqrt(Ks/Im) = 141 rad/s) at the default
h = 1 ms (z = 0.14) loses about 4e-5 of the total energy in 2 s here, so the conservation check
integrates with 4 sub-steps (h = 0.25 ms, z = 0.035); the error then falls as h^5 as it must.
With the physical damping on, this numerical loss is about 200 times smaller than Kd's.
"""
SUBSTEPS = 4
import math

import numpy as np
import pytest

core = pytest.importorskip("cdam_core._core")
from cdam_core.sim.parameters import plant_dict, plant_vector  # noqa: E402

UNDAMPED = dict(Kx=0, Ky=0, Kz=0, Kphi=0, Ktheta=0, Kpsi=0, Dm1=0, Dm2=0, Kd1=0, Kd2=0, Dl1=0,
                Dl2=0)


def _rot(qt):
    w, x, y, z = qt / np.linalg.norm(qt)
    return np.array([[w*w + x*x - y*y - z*z, 2*(x*y - w*z), 2*(x*z + w*y)],
                     [2*(x*y + w*z), w*w - x*x + y*y - z*z, 2*(y*z - w*x)],
                     [2*(x*z - w*y), 2*(y*z + w*x), w*w - x*x - y*y + z*z]])


def energy(p, x):
    """Total mechanical energy of state x (independent of the simulator's formulation)."""
    R = _rot(x[3:7])
    pos, v, w = x[0:3], x[11:14], x[14:17]
    q1, q2, th1, th2 = x[7:11]
    qd1, qd2, thd1, thd2 = x[17:21]
    g = p["g"]
    E = 0.5 * p["m_body"] * v @ v + 0.5 * (p["Jx"] * w[0]**2 + p["Jy"] * w[1]**2 + p["Jz"] * w[2]**2)
    E += p["m_body"] * g * pos[2]
    base = np.array([0.0, 0.0, -p["d_base"]])
    u1 = np.array([-math.sin(q1), 0, -math.cos(q1)])        # unit vector along link 1
    u2 = np.array([-math.sin(q1 + q2), 0, -math.cos(q1 + q2)])
    du1 = np.array([-math.cos(q1), 0, math.sin(q1)]) * qd1   # its time derivative in the body
    du2 = np.array([-math.cos(q1 + q2), 0, math.sin(q1 + q2)]) * (qd1 + qd2)
    links = [(p["m1"], base + p["lc1"] * u1, p["lc1"] * du1, q1, qd1, (p["I1xx"], p["I1yy"], p["I1zz"])),
             (p["m2"], base + p["l1"] * u1 + p["lc2"] * u2, p["l1"] * du1 + p["lc2"] * du2, q1 + q2,
              qd1 + qd2, (p["I2xx"], p["I2yy"], p["I2zz"])),
             (p["payload"], base + p["l1"] * u1 + p["l2"] * u2, p["l1"] * du1 + p["l2"] * du2, 0, 0, None)]
    for m, r, rd, ang, angd, inertia in links:
        vel = v + R @ (np.cross(w, r) + rd)
        E += 0.5 * m * vel @ vel + m * g * (pos + R @ r)[2]
        if inertia is not None:
            c, s = math.cos(ang), math.sin(ang)
            Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
            wl = Ry.T @ (w + np.array([0, angd, 0]))          # link rate in link axes
            E += 0.5 * (inertia[0] * wl[0]**2 + inertia[1] * wl[1]**2 + inertia[2] * wl[2]**2)
    for k, (th, q, thd) in enumerate(((th1, q1, thd1), (th2, q2, thd2)), start=1):
        d = th - q
        h = 0.5 * p[f"backlash{k}"]
        dz = math.copysign(max(abs(d) - h, 0.0), d)
        E += 0.5 * p[f"Im{k}"] * thd**2 + 0.5 * p[f"Ks{k}"] * dz**2 + 0.25 * p[f"K3_{k}"] * dz**4
    return E


def _initial():
    x = np.zeros(21)
    x[2] = 2.0
    qt = np.array([0.98, 0.1, -0.12, 0.08])
    x[3:7] = qt / np.linalg.norm(qt)
    x[7:11] = [0.6, -0.8, 0.65, -0.75]
    x[11:14] = [0.3, -0.2, 0.5]
    x[14:17] = [0.4, -0.6, 0.3]
    x[17:21] = [1.0, -1.5, 0.8, -1.2]
    return x


@pytest.mark.parametrize("gravity,extra", [(0.0, {}), (9.81, {}),
                                           (9.81, dict(payload=0.1, K3_1=5000, backlash2=0.02))])
def test_energy_conserved_over_10_s(gravity, extra):
    P = plant_vector(g=gravity if gravity > 0 else 1e-300, **UNDAMPED, **extra)
    p = plant_dict(P)
    x0 = _initial()
    U = np.zeros((10_000, 6))       # rotors stopped, motors unpowered: no input at all
    X = core.sim_open_loop(P, x0, U, 1e-3, max(SUBSTEPS, core.sim_substeps(P, 1e-3)))
    E = np.array([energy(p, x) for x in X[::250]])
    scale = abs(E[0]) if gravity == 0 else (abs(E[0]) + p["m_body"] * p["g"] * 50.0)
    assert np.ptp(X[:, 7]) > 0.5                    # the arm really swings
    assert np.max(np.abs(E - E[0])) / scale < 1e-6


def test_energy_changes_when_damped():
    """The check above can fail: with the cable damping on, energy is lost; and RK4's own
    dissipation converges at fifth order in h (the model, not the integrator, conserves)."""
    P = plant_vector(g=1e-300, **{**UNDAMPED, "Kd1": 0.02})
    p = plant_dict(P)
    X = core.sim_open_loop(P, _initial(), np.zeros((2000, 6)), 1e-3, 1)
    assert energy(p, X[-1]) < energy(p, X[0]) * (1 - 1e-3)
    P0 = plant_vector(g=1e-300, **UNDAMPED)
    p0 = plant_dict(P0)
    drift = []
    for ns in (1, 2):
        X = core.sim_open_loop(P0, _initial(), np.zeros((1000, 6)), 1e-3, ns)
        drift.append(abs(energy(p0, X[-1]) - energy(p0, X[0])))
    assert 16 < drift[0] / drift[1] < 64           # order 5: a factor 32 per halving
