"""Declared models of the flying machine, linear in their parameters (IDIM-LS).

``quadrotor``: PAPER.md equations (1)-(2) as used for identification in (8): the arm is extra
mass (``m`` is the whole vehicle's), the inertia is diagonal. Six equations (world forces and
body moments, Euler-angle rates as in (1)); the rotor-gyroscopic term ``Jm Om`` needs the rotor
speeds and is left out (it is below 1e-3 N m on the simulated flights)::

    X:         T (cphi stheta cpsi + sphi spsi)  = m X'' + Kx X'
    Y:         T (cphi stheta spsi - sphi cpsi)  = m Y'' + Ky Y'
    Z:         T cphi ctheta                     = m (Z'' + g) + Kz Z'
    tau_phi:   tau_phi   = Jx phi''   - Jy theta' psi' + Jz theta' psi' + Kphi phi'
    tau_theta: tau_theta = Jy theta'' - Jz phi' psi'   + Jx phi' psi'   + Ktheta theta'
    tau_psi:   tau_psi   = Jz psi''   - Jx phi' theta' + Jy phi' theta' + Kpsi psi'

``aerial_manipulator``: the same plus both cable-driven joints, (3)-(5) with the 2-link planar
arm hanging below the body (base parameters p1 = I1 + m1 lc1^2 + m2 l1^2, p2 = m2 l1 lc2,
p3 = I2 + m2 lc2^2, g1 = (m1 lc1 + m2 l1) g, g2 = m2 lc2 g; a = q1 + q2)::

    tau_m{k}: tau_mk = Imk thmk'' + Dmk thmk' + Ksk dk + Kdk dk'        (dk = thmk - qk)
    tau_l1:   0 = p1 w'' + p3 (w'' + q2'') + p2 [cos q2 (2 w'' + q2'') - sin q2 (2 w' q2' + q2'^2)]
                  + g1 G(q1) + g2 G(a) + Dl1 q1' - Ks1 d1 - Kd1 d1'
    tau_l2:   0 = p3 (w'' + q2'') + p2 [cos q2 w'' + sin q2 w'^2] + g2 G(a) + Dl2 q2'
                  - Ks2 d2 - Kd2 d2'

with w = theta + q1 the absolute angle of link 1 in the arm plane (the body pitches with the
arm) and G(a) = sin a fz - cos a fx, (fx, fz) the body-frame specific force over g (sin a in
hover): the links feel the body's pitch and acceleration. The arm's reaction on the body is left
out (the library effect ``arm_coupling``). Derivatives: the stated derivative filter on
every position, then *parallel filtering* (the same zero-phase low-pass applied to both sides of
every equation, as in the IDIM-LS practice of Gautier), so the measured inputs and the
regressors share one bandwidth. Default cutoff 2 Hz for the body channels (the flights' motion
lies below 2 Hz, and twice-differentiated position noise of 5-8 mm swamps any effect above
that: the Z'' noise grows as cutoff^2.5) and 20 Hz for the joint channels (the cable modes near
9 and 22 Hz are kept or attenuated on both sides alike). The positions are differentiated after
a 4 x wider low-pass (8 and 80 Hz), so the parallel filter alone sets the common bandwidth.
Edges are padded by one period of the cutoff and the first and last ``trim_seconds`` are left
out of the fit.

Estimation (``aerial_manipulator``): two-stage (lexicographic) IDIM-WLS. The link equations
are errors-in-variables equations. Their regressors hold the body's twice-differentiated
position and attitude noise (X'' at 8 Hz from 5 mm noise is about 0.07 g in the specific
force) and, at the body's band, they miss the arm-body exchange at the cable modes (about 25 %
of the cable torque stays in their residual even without noise); stacked with equal weight
they dragged the shared cable parameters (Ks 10 % low without noise, 37 % low at the default
noise, K3 nearly doubled). So the parameters they share with the motor equations (3), whose
input enters directly and whose regressors (motor angle, cable deflection) are clean, come
from the motor equations alone: first stage, every parameter with a column in a clean
equation (Im, Dm, Ks, Kd, the cable effects) from the clean equations (weights 1 / each
equation's RMS residual); second stage, the link parameters from the link equations with the
first stage held (estimation.stage_split). This is the limit a vanishing weight on the link
equations tends to (sessions 1-7 used a weight of 1e-3 for it); nothing is chosen. The second
stage's standard deviations carry the first stage's (estimation._two_stage_std). Measured on
"both", 10 s, seed 1: Ks1 within 0.1 % of 20 at 0 / 1 / 3 x noise. The link parameters (p1,
g1) remain biased low (g1 0.24 vs 0.31 at 1 x noise): regressor noise, not identifiable better
from these signals.

Decisions (:mod:`cdam_core.residual.selection`): on held-out time blocks, as for the axis
models. The declared flight model's open-loop windows do not simulate (far worse than holding
the last measurement), so :class:`~cdam_core.residual.validation.BlockedCV` scores the held-out
*equation* error of each window (each equation's squared residual over the declared model's
residual variance on it), one-sided paired Wilcoxon, Bonferroni over the candidates. An effect
that changes only link equations is decided the same way (there is no separate gain gate):
the mismatch of the link equations correlates in-sample with any velocity-shaped column, but a
column that only fits that mismatch on the training blocks does not lower it on the held-out
block. Without held-out windows (a record too short for them) no effect is claimed, as for
the axis models (:func:`cdam_core.residual.selection.select`: "too short to decide").
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.signals import as_signal
from cdam_core.models.greybox.declared import DerivativeFilter, GreyBoxModel, derived

G0 = 9.81
QUAD_INPUTS = ("T", "tau_phi", "tau_theta", "tau_psi")
QUAD_POSITIONS = ("phi", "theta", "psi", "X", "Y", "Z")


def thrust_direction(s: dict):
    """World components of the body z axis (Z-Y-X Euler angles), as in PAPER.md (1)."""
    return derived(s, "thrust_direction", ("phi", "theta", "psi"), lambda: _thrust_direction(s))


def _thrust_direction(s: dict):
    cf, sf = np.cos(s["phi"]), np.sin(s["phi"])
    ct, st = np.cos(s["theta"]), np.sin(s["theta"])
    cp, sp = np.cos(s["psi"]), np.sin(s["psi"])
    return cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct


class Quadrotor(GreyBoxModel):
    """PAPER.md (1)-(2) as the simplified model (8): six equations, see the module docstring."""

    name = "quadrotor"
    signals = QUAD_INPUTS + QUAD_POSITIONS
    inputs = QUAD_INPUTS
    positions = QUAD_POSITIONS
    equation_names = ("X", "Y", "Z", "tau_phi", "tau_theta", "tau_psi")
    parameter_names = ("m", "Kx", "Ky", "Kz", "Jx", "Jy", "Jz", "Kphi", "Ktheta", "Kpsi")
    bounds = {p: (0.0, float("inf")) for p in parameter_names}
    viscous = {}
    offset = {}
    cables = {}
    defaults = {k: k for k in QUAD_INPUTS + QUAD_POSITIONS}
    default_cutoff_hz = 2.0
    joint_cutoff_hz = 20.0
    derivative_ratio = 4.0
    # body derivatives used in the joint equations through a band this many times the joint
    # filter's (None: the body's own band). At zero noise 4 removes the link equations' mismatch
    # (the arm's reaction shakes the body at the cable modes), but the twice-differentiated
    # position and attitude noise then swamps them at the default noise, so the default is None
    body_in_joint_ratio = None
    trim_seconds = 0.5
    parallel_filter = True
    fixed_bands = True   # the documented bands below (module docstring)
    # IDIM-IV only: output error over every body and arm parameter costs minutes a fold (a
    # noise-free 20 s aerial-manipulator record: > 4 min in the OE Jacobian's rollouts), and
    # the open-loop body windows drift (770x the hold-last error on the README's flight)
    auto_estimators = ("iv",)
    max_steps = 8
    free_run_window = 1.0   # s; see freerun.free_run_error
    friction_width_search = True   # coulomb_friction searches its tanh width (effects.py)
    # the four rotor commands reach the rotors through the same ESCs: one shared delay
    # (effects.ActuatorDelay with channel "rotors"), never one per command
    shared_delays = {"rotors": QUAD_INPUTS}

    def prepare(self, t, raw: dict, filt: DerivativeFilter | None = None,
                extra: dict | None = None, timing: str = "sampled") -> dict:
        """As :meth:`GreyBoxModel.prepare`; ``psi`` is unwrapped first (logged in (-pi, pi]).
        ``timing`` "sampled" only: at the documented bands (2 and 20 Hz) half a sample of
        the flights' 1 kHz is a phase of 0.4 degrees or less."""
        if timing != "sampled":
            raise ValueError(f"timing: the {self.name} model takes 'sampled' only, got {timing!r}")
        if isinstance(raw, dict) and "psi" in raw:
            raw = dict(raw)
            raw["psi"] = np.unwrap(as_signal(raw["psi"], "psi"))
        filt = filt or DerivativeFilter(self.default_cutoff_hz)
        if filt.padlen is None:   # pad the edges by one period of the cutoff (fewer edge errors)
            dt = float(np.median(np.diff(as_signal(t, "t")))) if np.size(t) > 1 else 1.0
            filt = DerivativeFilter(filt.cutoff_hz, filt.order, int(round(1.0 / (filt.cutoff_hz * dt))))
        # derivatives through a band `derivative_ratio` times wider than the parallel filter
        # (which then sets the bandwidth of both sides alike, Gautier's decimation practice)
        r = self.derivative_ratio
        s = super().prepare(t, raw, DerivativeFilter(filt.cutoff_hz * r, filt.order, filt.padlen),
                            extra)
        s["filter"] = filt
        jf = self.joint_filter(filt)
        jd = DerivativeFilter(jf.cutoff_hz * r, jf.order, jf.padlen)
        for p in self.positions:
            if p not in QUAD_POSITIONS:   # joint signals: the wider band
                s[p], s[p + "_d"], s[p + "_dd"] = jd.apply(s[p + "_raw"], s["dt"])
        if self.body_in_joint_ratio and any(p not in QUAD_POSITIONS for p in self.positions):
            # the body's motion as the joint equations see it: through the joints' band
            bd = DerivativeFilter(jf.cutoff_hz * self.body_in_joint_ratio, jf.order, jf.padlen)
            for p in QUAD_POSITIONS:
                _, s[p + "_dj"], s[p + "_ddj"] = bd.apply(s[p + "_raw"], s["dt"])
        s["filter_joint"] = jf
        return self.augment(s)

    def joint_filter(self, filt: DerivativeFilter) -> DerivativeFilter:
        return DerivativeFilter(self.joint_cutoff_hz, filt.order, filt.padlen)

    def equation_filter(self, eq: str, s: dict):
        """The parallel filter of equation ``eq``: body equations at the stated cutoff, joint
        equations at ``joint_cutoff_hz``."""
        if eq in self.equation_names[:6]:
            return s["filter"]
        return s.get("filter_joint", s["filter"])

    def equations(self, s: dict) -> dict:
        # products of whole-record signals are kept while those signals are the same arrays
        # (declared.derived): a structure search changes one input or one column at a time
        fx, fy, fz = derived(s, "thrust_forces", ("T", "phi", "theta", "psi"),
                             lambda: tuple(s["T"] * u for u in thrust_direction(s)))
        pd, td, yd = s["phi_d"], s["theta_d"], s["psi_d"]
        zg, tyn, typ, pyn, pyp, ptn, ptp = derived(
            s, "rate_products", ("Z_dd", "phi_d", "theta_d", "psi_d"),
            lambda: (s["Z_dd"] + G0, -td * yd, td * yd, -pd * yd, pd * yd, -pd * td, pd * td))
        return {
            "X": (fx, {"m": s["X_dd"], "Kx": s["X_d"]}),
            "Y": (fy, {"m": s["Y_dd"], "Ky": s["Y_d"]}),
            "Z": (fz, {"m": zg, "Kz": s["Z_d"]}),
            "tau_phi": (s["tau_phi"], {"Jx": s["phi_dd"], "Jy": tyn, "Jz": typ, "Kphi": pd}),
            "tau_theta": (s["tau_theta"], {"Jy": s["theta_dd"], "Jz": pyn, "Jx": pyp,
                                           "Ktheta": td}),
            "tau_psi": (s["tau_psi"], {"Jz": s["psi_dd"], "Jx": ptn, "Jy": ptp, "Kpsi": yd}),
        }

    def reference(self, eq: str, s: dict, theta: dict):
        return None   # normalise by the equation's own left side (force or moment)


class AerialManipulator(Quadrotor):
    """Model (8) plus both cable-driven joints of the 2-link arm (module docstring)."""

    name = "aerial_manipulator"
    signals = QUAD_INPUTS + ("tau_m1", "tau_m2") + QUAD_POSITIONS + (
        "theta_m1", "theta_m2", "q1", "q2")
    inputs = QUAD_INPUTS + ("tau_m1", "tau_m2")
    positions = QUAD_POSITIONS + ("theta_m1", "theta_m2", "q1", "q2")
    equation_names = Quadrotor.equation_names + ("tau_m1", "tau_l1", "tau_m2", "tau_l2")
    parameter_names = Quadrotor.parameter_names + (
        "Im1", "Dm1", "Ks1", "Kd1", "Im2", "Dm2", "Ks2", "Kd2", "p1", "p2", "p3", "g1", "g2",
        "Dl1", "Dl2")
    bounds = {**Quadrotor.bounds, **{p: (0.0, float("inf")) for p in (
        "Im1", "Dm1", "Ks1", "Kd1", "Im2", "Dm2", "Ks2", "Kd2", "Dl1", "Dl2")}}
    viscous = {"tau_m1": ("Dm1", "theta_m1_d"), "tau_m2": ("Dm2", "theta_m2_d"),
               "tau_l1": ("Dl1", "q1_d"), "tau_l2": ("Dl2", "q2_d")}
    # link equation -> (motor equation, deflection, deflection rate, stiffness parameter)
    cables = {"tau_l1": ("tau_m1", "defl1", "defl1_d", "Ks1"),
              "tau_l2": ("tau_m2", "defl2", "defl2_d", "Ks2")}
    defaults = {k: k for k in QUAD_INPUTS + ("tau_m1", "tau_m2") + QUAD_POSITIONS + (
        "theta_m1", "theta_m2", "q1", "q2")}
    max_steps = 10
    weighted = True      # IDIM-WLS (estimation.set_equation_weights), see the module docstring
    # errors-in-variables equations: estimated in a second stage, after the clean equations
    # (module docstring; estimation.stage_split)
    eiv_equations = ("tau_l1", "tau_l2")
    joint_depth = 0.08   # m, joint 1 below the body origin (geometry of the build, not fitted)

    def augment(self, s: dict) -> dict:
        for k in (1, 2):
            s[f"defl{k}"] = s[f"theta_m{k}"] - s[f"q{k}"]
            s[f"defl{k}_d"] = s[f"theta_m{k}_d"] - s[f"q{k}_d"]
        return s

    def equations(self, s: dict) -> dict:
        eqs = super().equations(s)
        keys = ("q1", "q2", "q1_d", "q1_dd", "q2_d", "q2_dd", "theta_d", "theta_dd",
                "theta_dj", "theta_ddj", "phi", "theta", "psi", "X_dd", "Y_dd", "Z_dd",
                "X_ddj", "Y_ddj", "Z_ddj")
        zero, l1, l2 = derived(s, f"link_columns {self.joint_depth!r}",
                               tuple(k for k in keys if k in s), lambda: self._link_columns(s))
        for k in (1, 2):
            d, dd = s[f"defl{k}"], s[f"defl{k}_d"]
            eqs[f"tau_m{k}"] = (s[f"tau_m{k}"], {f"Im{k}": s[f"theta_m{k}_dd"],
                                                 f"Dm{k}": s[f"theta_m{k}_d"],
                                                 f"Ks{k}": d, f"Kd{k}": dd})
        nd1, ndd1, nd2, ndd2 = derived(
            s, "cable_columns", ("defl1", "defl1_d", "defl2", "defl2_d"),
            lambda: (-s["defl1"], -s["defl1_d"], -s["defl2"], -s["defl2_d"]))
        eqs["tau_l1"] = (zero, {**l1, "Dl1": s["q1_d"], "Ks1": nd1, "Kd1": ndd1})
        eqs["tau_l2"] = (zero, {**l2, "Dl2": s["q2_d"], "Ks2": nd2, "Kd2": ndd2})
        return eqs

    def _link_columns(self, s: dict) -> tuple:
        """The link equations' columns that hold the arm's and the body's motion only."""
        q1, q2 = s["q1"], s["q2"]
        # link 1's absolute rates in the arm plane (the body pitches with it)
        td, tdd = s.get("theta_dj", s["theta_d"]), s.get("theta_ddj", s["theta_dd"])
        w1, w1dd = td + s["q1_d"], tdd + s["q1_dd"]
        q2d, q2dd = s["q2_d"], s["q2_dd"]
        c2, s2 = np.cos(q2), np.sin(q2)
        gx, gz = self.specific_force(s)
        zero = 0.0 * q1
        g1 = np.sin(q1) * gz - np.cos(q1) * gx
        g2 = np.sin(q1 + q2) * gz - np.cos(q1 + q2) * gx
        l1 = {"p1": w1dd, "p3": w1dd + q2dd,
              "p2": c2 * (2 * w1dd + q2dd) - s2 * (2 * w1 * q2d + q2d ** 2),
              "g1": g1, "g2": g2}
        l2 = {"p3": w1dd + q2dd, "p2": c2 * w1dd + s2 * w1 ** 2, "g2": g2}
        return zero, l1, l2

    def specific_force(self, s: dict):
        """Body-frame x and z specific force at joint 1 over g: (R^T (p'' + g e_z) + the
        joint's acceleration from the body's pitch, (-d theta'', d theta'^2)) / g; 'gravity' as
        the swinging links feel it (0, 1 in hover)."""
        keys = ("phi", "theta", "psi", "X_dd", "Y_dd", "Z_dd", "theta_d", "theta_dd")
        keys += tuple(k for k in ("X_ddj", "Y_ddj", "Z_ddj", "theta_dj", "theta_ddj") if k in s)
        return derived(s, f"specific_force {self.joint_depth!r}", keys,
                       lambda: self._specific_force(s))

    def _specific_force(self, s: dict):
        cf, sf = np.cos(s["phi"]), np.sin(s["phi"])
        ct, st = np.cos(s["theta"]), np.sin(s["theta"])
        cp, sp = np.cos(s["psi"]), np.sin(s["psi"])
        def get(k):   # the body's derivatives through the joints' band where there are
            return s.get(k[:-1] + "dj" if k.endswith("_d") else k + "j", s[k])
        ax, ay, az = get("X_dd"), get("Y_dd"), get("Z_dd") + G0
        bx = ct * cp * ax + ct * sp * ay - st * az
        bz = (cf * st * cp + sf * sp) * ax + (cf * st * sp - sf * cp) * ay + cf * ct * az
        d = self.joint_depth
        return (bx - d * get("theta_dd")) / G0, (bz + d * get("theta_d") ** 2) / G0

    def reference(self, eq: str, s: dict, theta: dict):
        if eq in self.cables:   # the cable torque the link equation balances
            _, d, dd, ks = self.cables[eq]
            k = eq[-1]
            return theta.get(ks, 0.0) * s[d] + theta.get(f"Kd{k}", 0.0) * s[dd]
        return None
