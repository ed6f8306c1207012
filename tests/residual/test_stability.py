"""[greybox] item 4: the model linearised at rest, its eigenvalues against the closed form of
the linear second-order system M x'' + D x' + K x = 0 (plain numpy, written here), and a model
that falls over (a gravity term of the wrong sign) said to be unstable."""
import numpy as np
import pytest

from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.residual.analyse import analyse

from joint_generator import Joint


def _closed_form(M, D, K):
    n = M.shape[0]
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ D]])
    return np.sort_complex(np.linalg.eigvals(A))


@pytest.fixture(scope="module")
def joint():
    r = Joint(duration=4.0).record()
    U = r["tau_m"][:, None]
    Y = np.column_stack([r["theta_m"], r["q"]])
    return GreyBox("flexible_joint", dt=float(r["t"][1] - r["t"][0]), cutoff_hz=100.0).fit(U, Y)


@pytest.mark.parametrize("G", [0.6, 0.0, -0.6])
def test_flexible_joint_eigenvalues_match_the_closed_form(joint, G):
    p = {"Im": 0.02, "Dm": 0.05, "Ks": 40.0, "Kd": 0.05, "I": 0.1, "Dl": 0.1}
    g = joint.set_parameters({**p, "G": G})
    M = np.diag([p["Im"], p["I"]])
    K = np.array([[p["Ks"], -p["Ks"]], [-p["Ks"], p["Ks"] + G]])
    D = np.array([[p["Dm"] + p["Kd"], -p["Kd"]], [-p["Kd"], p["Dl"] + p["Kd"]]])
    ref = _closed_form(M, D, K)
    got = np.sort_complex(g.linearised_eigenvalues())
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)
    st = g.stability()
    assert st["stable"] == bool(np.max(ref.real) <= 1e-9)
    assert st["stable"] is (G >= 0)      # G < 0: an inverted pendulum, it falls over


def test_rigid_axis_is_an_integrator_and_a_decay():
    t = np.arange(3000) * 1e-3
    q = 0.2 * np.sin(2 * np.pi * 0.7 * t)
    tau = 0.5 * np.gradient(np.gradient(q, 1e-3), 1e-3) + 2.0 * np.gradient(q, 1e-3)
    g = GreyBox("rigid_axis", dt=1e-3, cutoff_hz=50.0).fit(tau[:, None], q[:, None])
    g.set_parameters({"M": 0.5, "Fv": 2.0, "offset": 0.0, "G": 0.0, "Gc": 0.0})
    lam = np.sort(g.linearised_eigenvalues().real)
    np.testing.assert_allclose(lam, [-4.0, 0.0], atol=1e-5)
    assert g.stability()["stable"]


def test_the_residual_report_states_stability():
    r = Joint(duration=6.0).record()
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False)
    st = sel.settings["stability"]
    assert st["stable"] is True
    # a horizontal joint turns freely (one eigenvalue at 0), every other mode decays
    lam = np.array(st["eigenvalues"])
    assert np.sum(np.abs(lam[:, 0]) < 1e-3) >= 1 and np.all(lam[:, 0] < 1e-3)
