"""arm_coupling's causal columns (cdam_core.models.greybox.causal): the jets are the plain
second differences of the local trajectories, computed here independently (rotation matrix
written out, w on three points, (w2 - 2 w1 + w0) / dt^2); no row depends on a later one; and
in float32 they stay near float32 rounding of the column, where the plain second difference
of float32 values loses about six digits (the float32 error bound the board relies on)."""
import numpy as np
import pytest
from scipy import signal as sps

from cdam_core.models.greybox import causal as ca

DT = 1e-3
N = 3000


def _record(seed=0):
    """Smooth flight-like signals (sums of sines, plain numpy) plus small measurement noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    out = {}
    for name, amp in zip(ca.ARM_SIGNALS, (0.2, 0.2, 2.5, 3.0, 3.0, 1.5, 0.8, 0.6)):
        f = rng.uniform(0.2, 3.0, 3)
        ph = rng.uniform(0, 2 * np.pi, 3)
        x = amp * np.sum(np.sin(2 * np.pi * f[:, None] * t + ph[:, None]), axis=0) / 3
        out[name] = x + 1e-4 * rng.standard_normal(N)
    out["psi"] = np.angle(np.exp(1j * out["psi"]))     # logged wrapped
    return out


def _sos():
    """The two bands as the board holds them (causal.arm_sections: b0 b1 b2 1 alpha1 alpha2)."""
    return ca.arm_sections(4, 8.0, DT), ca.arm_sections(4, 80.0, DT)


def _as_sos(sec):
    """scipy's sections of the same filter: a1 = alpha1 - 2, a2 = alpha2 - alpha1 + 1."""
    sos = np.array(sec, dtype=float)
    sos[:, 4], sos[:, 5] = sec[:, 4] - 2.0, sec[:, 5] - sec[:, 4] + 1.0
    return sos


def _trajectories(raw):
    """Per signal the three points (v - c, v, v + p) from the definitions (filtered
    increments, plain scipy), independent of the module's jets."""
    bs, js = _sos()
    out = {}
    for n in ca.ARM_SIGNALS:
        a = raw[n]
        d = np.r_[0.0, np.diff(a)]
        if n == "psi":
            d = (d + np.pi) % (2 * np.pi) - np.pi
        p = sps.sosfilt(_as_sos(bs if n in ("phi", "theta", "psi", "X", "Y", "Z") else js), d)
        c = np.r_[0.0, p[:-1]]
        v = np.r_[a[:1], a[:-1]]
        out[n] = (v - c, v, v + p)
    return out


def _rot(f, t, p):
    cf, sf, ct, st, cp, sp = np.cos(f), np.sin(f), np.cos(t), np.sin(t), np.cos(p), np.sin(p)
    return np.array([[ct * cp, cp * st * sf - sp * cf, cf * st * cp + sf * sp],
                     [ct * sp, sp * st * sf + cp * cf, cf * st * sp - sf * cp],
                     [-st, ct * sf, cf * ct]])


def test_force_columns_are_second_differences_of_the_local_trajectory():
    raw = _record()
    bs, js = _sos()
    cols = ca.arm_columns(raw, DT, bs, js, ("X", "Y", "Z"), 9.81)
    tr = _trajectories(raw)
    for i, ch in enumerate("XYZ"):
        w = []
        for m in range(3):
            R = _rot(tr["phi"][m], tr["theta"][m], tr["psi"][m])
            q1, q12 = tr["q1"][m], tr["q1"][m] + tr["q2"][m]
            bx, bz = R[i, 0], R[i, 2]
            w.append(np.array([-bz, -np.sin(q1) * bx - np.cos(q1) * bz,
                               -np.sin(q12) * bx - np.cos(q12) * bz]))
        ref = (w[2] - 2 * w[1] + w[0]) / DT ** 2
        for n, name in enumerate(("c0", "c1", "c2")):
            rms = np.sqrt(np.mean(ref[n] ** 2))
            # the reference itself cancels to ~1e-16 / dt^2 of |w|
            np.testing.assert_allclose(cols[ch][name], ref[n], rtol=0, atol=1e-8 + 1e-8 * rms)


def test_moment_columns_from_the_definitions():
    raw = _record(1)
    bs, js = _sos()
    cols = ca.arm_columns(raw, DT, bs, js, ("tau_theta", "tau_phi"), 9.81)
    tr = _trajectories(raw)
    now = {n: tr[n][2] for n in ca.ARM_SIGNALS}
    rate = {n: (tr[n][2] - tr[n][1]) / DT for n in ca.ARM_SIGNALS}
    rate0 = {n: (tr[n][1] - tr[n][0]) / DT for n in ca.ARM_SIGNALS}
    accel = {n: (tr[n][2] - 2 * tr[n][1] + tr[n][0]) / DT ** 2 for n in ca.ARM_SIGNALS}
    R = _rot(now["phi"], now["theta"], now["psi"])
    acc = np.array([accel["X"], accel["Y"], accel["Z"] + 9.81])
    ax, ay, az = (np.einsum("ij,ij->j", R[:, k], acc) for k in range(3))
    q1, q2 = now["q1"], now["q2"]
    q1p, q2p = tr["q1"][1], tr["q2"][1]

    def d(h1, h0):
        return (h1 - h0) / DT

    th, th0 = rate["theta"], rate0["theta"]
    ref = {"c0": -ax, "c1": -np.cos(q1) * ax + np.sin(q1) * az,
           "c2": -np.cos(q1 + q2) * ax + np.sin(q1 + q2) * az,
           "dc1": d(np.cos(q1) * (2 * th + rate["q1"]), np.cos(q1p) * (2 * th0 + rate0["q1"])),
           "dc2": d(np.cos(q1 + q2) * (2 * th + rate["q1"] + rate["q2"]),
                    np.cos(q1p + q2p) * (2 * th0 + rate0["q1"] + rate0["q2"])),
           "p2": d(np.cos(q2) * (2 * th + 2 * rate["q1"] + rate["q2"]),
                   np.cos(q2p) * (2 * th0 + 2 * rate0["q1"] + rate0["q2"])),
           "I1": accel["q1"], "I12": accel["q1"] + accel["q2"]}
    for name, r in ref.items():
        got = cols["tau_theta"][name]
        # the reference's own float64 cancellation (|x| 1e-16 / dt^2), far below the columns
        np.testing.assert_allclose(got, r, rtol=0, atol=1e-6 * (np.sqrt(np.mean(r ** 2)) + 1))
    ph, ph0 = rate["phi"], rate0["phi"]
    ref = {"c0": ay, "c1": np.cos(q1) * ay, "c2": np.cos(q1 + q2) * ay,
           "dc1": d(np.cos(q1) * ph, np.cos(q1p) * ph0),
           "dc2": d(np.cos(q1 + q2) * ph, np.cos(q1p + q2p) * ph0),
           "p2": d(np.cos(q2) * ph, np.cos(q2p) * ph0)}
    for name, r in ref.items():
        np.testing.assert_allclose(cols["tau_phi"][name], r, rtol=0,
                                   atol=1e-6 * (np.sqrt(np.mean(r ** 2)) + 1))


def test_no_row_depends_on_a_later_row():
    raw = _record(2)
    bs, js = _sos()
    chans = ("X", "Y", "Z", "tau_theta", "tau_phi")
    a = ca.arm_columns(raw, DT, bs, js, chans, 9.81)
    cut = 1700
    changed = {n: np.r_[v[:cut], v[cut:] + 0.3] for n, v in raw.items()}
    b = ca.arm_columns(changed, DT, bs, js, chans, 9.81)
    for ch in chans:
        for name in a[ch]:
            np.testing.assert_array_equal(a[ch][name][:cut], b[ch][name][:cut])
            assert np.any(a[ch][name][cut:] != b[ch][name][cut:])


def test_float32_error_is_at_the_columns_rounding_level():
    """The same formulas in float32 (what the board computes) against float64 on the same
    float32 record and coefficients: within 2e-5 of each column's RMS (measured 6.6e-6; with
    scipy's direct form II transposed in float32 instead of the increment form, 6.7e-5: poles
    within 0.05 of 1), while the plain second difference w[k] - 2 w[k-1] + w[k-2] of float32
    values w errs by eps |w| / dt^2 (3.2e-3 of the RMS on these strongly excited signals,
    1e6 eps |w| / RMS in general)."""
    raw = _record(3)
    bs, js = _sos()
    ref = ca.arm_columns(raw, DT, bs, js, ("X", "Y", "Z"), 9.81)
    raw32 = {n: v.astype(np.float32) for n, v in raw.items()}
    ref32in = ca.arm_columns({n: v.astype(np.float64) for n, v in raw32.items()}, DT, bs, js,
                             ("X", "Y", "Z"), 9.81)
    got = ca.arm_columns(raw32, np.float32(DT), bs, js, ("X", "Y", "Z"), np.float32(9.81))
    tr = _trajectories({n: v.astype(np.float64) for n, v in raw32.items()})
    worst_jet, worst_plain = 0.0, np.inf
    for i, ch in enumerate("XYZ"):
        w32 = []
        for m in range(3):
            R = _rot(*(tr[n][m].astype(np.float32) for n in ("phi", "theta", "psi")))
            w32.append((-R[i, 2]).astype(np.float32))
        plain = ((w32[2] - np.float32(2) * w32[1]) + w32[0]) / np.float32(DT * DT)
        for name in ("c0", "c1", "c2"):
            assert got[ch][name].dtype == np.float32
            rms = np.sqrt(np.mean(ref32in[ch][name] ** 2))
            e = np.max(np.abs(got[ch][name] - ref32in[ch][name])) / rms
            worst_jet = max(worst_jet, e)
        rms0 = np.sqrt(np.mean(ref32in[ch]["c0"] ** 2))
        worst_plain = min(worst_plain, np.max(np.abs(plain - ref32in[ch]["c0"])) / rms0)
    print(f"float32 error / column RMS: jets {worst_jet:.2e}, plain second difference "
          f"{worst_plain:.2e}")
    assert worst_jet < 2e-5
    assert worst_plain > 100 * worst_jet
    # the float32 record's rounding itself moves the float64 columns by less than that
    for ch in "XYZ":
        for name in ("c0", "c1", "c2"):
            rms = np.sqrt(np.mean(ref[ch][name] ** 2))
            assert np.max(np.abs(ref[ch][name] - ref32in[ch][name])) < 1e-2 * rms


def test_sections_are_the_butterworth_and_the_increment_form_its_recursion():
    """arm_sections is scipy's Butterworth to float32 precision (relative, also in alpha1 and
    alpha2); the board's increment form (delta_sosfilt, float64 here) runs the same recursion
    as scipy's sosfilt on those numbers."""
    ref = sps.butter(4, 8.0, fs=1 / DT, output="sos")
    sec = ca.arm_sections(4, 8.0, DT)
    np.testing.assert_allclose(sec[:, :3], ref[:, :3], rtol=1e-7)
    np.testing.assert_allclose(sec[:, 4], ref[:, 4] + 2, rtol=1e-7)
    np.testing.assert_allclose(sec[:, 5], 1 + ref[:, 4] + ref[:, 5], rtol=1e-7)
    x = np.random.default_rng(4).standard_normal(2000) * 1e-3
    want = sps.sosfilt(_as_sos(sec), x)
    np.testing.assert_allclose(ca.delta_sosfilt(sec, x), want, rtol=0,
                               atol=1e-12 * np.max(np.abs(want)))


def test_bad_channel_and_cutoff_are_named():
    raw = _record()
    bs, js = _sos()
    with pytest.raises(ValueError, match="channel: arm_coupling has no channel 'q1'"):
        ca.arm_columns(raw, DT, bs, js, ("q1",), 9.81)
    with pytest.raises(ValueError, match="cutoff_hz: 600 Hz is not below the Nyquist"):
        ca.arm_sections(4, 600.0, DT)
