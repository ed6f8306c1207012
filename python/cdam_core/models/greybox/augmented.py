"""The grey-box model as a model kind: a declared model plus the effects found, fitted, saved,
loaded and predicted like every other kind (``kind: "greybox"`` in the model file).

Inputs U: the declared model's inputs (``tau`` / ``tau_m`` / the rotor commands ...) followed by
the measured channels of its ``external_force`` effects (``extra_columns``); outputs Y: its
positions. Sample time ``dt`` is part of the model (the effects shift and differentiate in time).

Prediction integrates the equations forward (semi-implicit Euler, ``substeps`` per sample; the
one integrator of the grey-box models: :mod:`cdam_core.models.greybox.freerun` runs the residual
loop's free runs through it; its simulation windows may use RK4 instead, ``windows``). The
equations are written once, in numpy; the rollout runs them compiled (:mod:`.trace` records
them as a tape for ``_core.greybox_rollout``), the numpy step loop being its reference and
fallback. The state at a row is the measured
position and the backward difference of the last two measured positions, so ``t0 = 2``: one-step
predicts row t from rows t-2, t-1 and the input at t-1; k-step integrates k samples from the
state at t-k, all windows at once; free run integrates the whole segment from its first two rows.
Effects whose columns need the whole record (``arm_coupling``: the arm's measured motion acting
on the body) take them from the measured outputs in every mode, as ``cdam residual``'s free run
does. The inertia matrix (how the accelerations enter the equations) and the number of substeps
are fixed when the model is fitted (from the zero state), so a loaded model predicts exactly as
the fitted one.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from cdam_core.base.checks import as_2d
from cdam_core.models.greybox import stickslip as ss
from cdam_core.models.greybox import trace as tr
from cdam_core.models.greybox.declared import DerivativeFilter, SignalFilters
from cdam_core.models.greybox.effects import LIBRARY, Effect
from cdam_core.models.greybox.estimation import apply_effects, design, fit as idim_fit
from cdam_core.models.greybox.registry import MODEL_NAMES, get_model
from cdam_core.models.protocol import Model

__all__ = ["GreyBox"]

MAX_SUBSTEPS = 10000
# the rollout's integrators (GreyBox._rollout): the model kind's semi-implicit Euler, RK4 with
# a dry friction's sign held over each step, RK4 with the dry friction's stick-slip
INTEGRATORS = ("euler", "rk4", "rk4-stickslip")


def _effect_to_dict(e: Effect) -> dict:
    out = {"name": e.name}
    for f in dataclasses.fields(e):
        v = getattr(e, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def _effect_from_dict(d: dict, where: str) -> Effect:
    if not isinstance(d, dict) or d.get("name") not in LIBRARY:
        raise ValueError(f"{where}.name: unknown effect {d.get('name') if isinstance(d, dict) else d!r}")
    cls = LIBRARY[d["name"]]
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kw = {}
    for key, value in d.items():
        if key == "name":
            continue
        if key not in fields:
            raise ValueError(f"{where}.{key}: not a field of {d['name']}")
        default = fields[key].default
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):   # a count of samples (rest_reach)
            ok = isinstance(value, int) and not isinstance(value, bool) and value >= 0
        elif isinstance(default, float):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
            value = float(value) if ok else value
        elif isinstance(default, tuple):
            ok = isinstance(value, list) and all(isinstance(x, str) for x in value)
            value = tuple(value) if ok else value
        else:
            ok = isinstance(value, str)
        if not ok:
            raise ValueError(f"{where}.{key}: wrong type {type(value).__name__}")
        kw[key] = value
    if "channel" not in kw:
        raise ValueError(f"{where}.channel: missing")
    return cls(**kw)


class GreyBox(Model):
    """A declared grey-box model (``rigid_axis``, ``flexible_joint``, ``quadrotor``,
    ``aerial_manipulator``) with library effects, estimated by IDIM-LS (see the module doc)."""

    kind = "greybox"
    compiled = True   # False: the numpy rollout only (the compiled path's reference)

    def __init__(self, declared: str = "rigid_axis", dt: float | None = None, effects=(),
                 fixed: dict | None = None, cutoff_hz: float | None = None, filter_order: int = 4,
                 extra_columns=()):
        self.declared = declared
        self.dt = dt
        self.effects = tuple(effects)
        self.fixed = dict(fixed or {})
        self.cutoff_hz = cutoff_hz
        self.filter_order = filter_order
        self.extra_columns = tuple(extra_columns)
        self.n_outputs_ = None

    # -- structure -----------------------------------------------------------------------------
    @property
    def t0(self) -> int:
        return 2

    def _structure(self):
        """Check the settings; returns the declared model."""
        m = get_model(self.declared, self.fixed)
        if self.dt is None or not np.isfinite(self.dt) or self.dt <= 0:
            raise ValueError(f"dt: the sample time must be a positive number, got {self.dt!r}")
        if isinstance(self.cutoff_hz, dict):
            for k, v in self.cutoff_hz.items():
                if k not in m.positions:
                    raise ValueError(f"filter.cutoff_per_signal_hz: {k!r} is not a position of "
                                     f"{m.name} ({', '.join(m.positions)})")
                if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                    raise ValueError(f"filter.cutoff_per_signal_hz.{k}: not a positive number")
        ext = set(self.extra_columns)
        channels = set(m.equation_names) | set(m.inputs) | set(getattr(m, "shared_delays", {}))
        for j, e in enumerate(self.effects):
            if not isinstance(e, Effect):
                raise ValueError(f"effects[{j}]: not an Effect")
            if e.channel not in channels or not e.applies_to(m):
                raise ValueError(f"effects[{j}]: {e.key} does not apply to {m.name}")
            if getattr(e, "column", None) and e.column not in ext:
                raise ValueError(f"effects[{j}]: column {e.column!r} not in extra_columns")
        return m

    def _signals(self, m, U, Y):
        ni = len(m.inputs)
        raw = {name: U[:, i] for i, name in enumerate(m.inputs)}
        raw.update({p: Y[:, j] for j, p in enumerate(m.positions)})
        extra = {c: U[:, ni + j] for j, c in enumerate(self.extra_columns)}
        return raw, extra

    def _filter(self, m) -> DerivativeFilter:
        if isinstance(self.cutoff_hz, dict):
            return SignalFilters.of(self.cutoff_hz, int(self.filter_order))
        return DerivativeFilter(m.default_cutoff_hz if self.cutoff_hz is None else self.cutoff_hz,
                                int(self.filter_order))

    # -- fit -----------------------------------------------------------------------------------
    def _fit(self, U, Y):
        m = self._structure()
        if U.shape[1] != len(m.inputs) + len(self.extra_columns):
            raise ValueError(f"U: {self.declared} with extra columns {list(self.extra_columns)} "
                             f"takes {len(m.inputs) + len(self.extra_columns)} columns "
                             f"({', '.join(m.inputs + self.extra_columns)}), got {U.shape[1]}")
        if Y.shape[1] != len(m.positions):
            raise ValueError(f"Y: {self.declared} has {len(m.positions)} outputs "
                             f"({', '.join(m.positions)}), got {Y.shape[1]}")
        t = np.arange(U.shape[0]) * float(self.dt)
        raw, extra = self._signals(m, U, Y)
        sig = m.prepare(t, raw, self._filter(m), extra or None)
        f = idim_fit(m, sig, self.effects, bounded=True)
        self._set(m, f.theta, f.std, f.estimated, U.shape[1], Y.shape[1])

    @classmethod
    def from_fit(cls, fitted, dt: float, cutoff_hz: float | None = None, filter_order: int = 4,
                 extra_columns=()) -> "GreyBox":
        """The model of an IDIM fit (e.g. ``cdam residual``'s final, augmented fit)."""
        m = fitted.model
        g = cls(m.name, dt, fitted.effects, m.fixed, cutoff_hz, filter_order, extra_columns)
        m = g._structure()
        g._set(m, fitted.theta, fitted.std, fitted.estimated,
               len(m.inputs) + len(g.extra_columns), len(m.positions))
        return g

    def _set(self, m, theta, std, estimated, n_in, n_out, substeps=None):
        self.theta_ = {k: float(v) for k, v in theta.items()}
        self.std_ = {k: (None if v is None or not np.isfinite(v) else float(v))
                     for k, v in std.items()}
        self.estimated_ = list(estimated)
        self.n_inputs_, self.n_outputs_ = int(n_in), int(n_out)
        self._m = m
        self._inertia = self._inertia_matrix()
        self.substeps_ = int(substeps) if substeps is not None else self._choose_substeps()

    # -- equations on a batch of states ---------------------------------------------------------
    def _state(self, x, v, a, u: dict, ex: dict, k, t) -> dict:
        m = self._m
        s = {"t": t, "extra": ex, "k": k, "dt": float(self.dt)}
        s.update(u)
        for j, p in enumerate(m.positions):
            s[p], s[p + "_d"], s[p + "_dd"] = x[:, j], v[:, j], a[:, j]
        return m.augment(s)

    def _terms(self, s: dict, pre_at: dict, effects=None) -> dict:
        """``{equation: (y, {parameter: column})}`` at the states in ``s``; ``pre_at``: the
        whole-record effect columns at the states' rows (``{effect key: {name: column}}``)."""
        m = self._m
        effects = self.effects if effects is None else effects
        for e in effects:
            s = e.transform_state(s, m)
        eqs = {k: (y, dict(c)) for k, (y, c) in m.equations(s).items()}
        for e in effects:
            cols = {e.channel: pre_at[e.key]} if e.key in pre_at else e.regressors(s, m)
            for eq, c in cols.items():
                eqs[eq][1].update(c)
        return eqs

    def _errors(self, s: dict, pre: dict, effects=None, theta=None) -> np.ndarray:
        """Equation errors (equations, W) of the states in ``s``; ``theta``: parameter values
        (default the model's; arrays of W values give each state its own)."""
        theta = self.theta_ if theta is None else theta
        pre_at = {key: {n: c[s["k"]] for n, c in cols.items()} for key, cols in pre.items()}
        eqs = self._terms(s, pre_at, effects)
        W = s[self._m.positions[0]].shape[0]
        out = np.empty((len(eqs), W))
        for i, (y, cols) in enumerate(eqs.values()):
            r = np.broadcast_to(np.asarray(y, dtype=float), (W,)).copy()
            for p, c in cols.items():
                r -= theta[p] * np.asarray(c, dtype=float)
            out[i] = r
        return out

    def _zero_state(self, W=1):
        m = self._m
        n = len(m.positions)
        z = np.zeros((W, n))
        u = {name: np.zeros(W) for name in m.inputs}
        ex = {c: np.zeros(W) for c in self.extra_columns}
        return z, u, ex

    def _inertia_matrix(self) -> np.ndarray:
        """How the accelerations enter the equation errors, at the zero state (e = b - A a)."""
        m = self._m
        n = len(m.positions)
        z, u, ex = self._zero_state(n + 1)
        a = np.vstack([np.zeros(n), np.eye(n)])
        k = np.zeros(n + 1, dtype=int)
        pre = self._zero_pre(n + 1)
        e = self._errors(self._state(z, z, a, u, ex, k, np.zeros(n + 1)), pre)
        A = e[:, :1] - e[:, 1:]
        if A.shape[0] != n or np.linalg.cond(A) > 1e12:
            raise ValueError("theta: the estimated inertia matrix is singular; cannot simulate")
        return np.linalg.inv(A)

    def _zero_pre(self, W):
        return {e.key: {n: np.zeros(W) for n in self._pre_names(e)} for e in self.effects
                if hasattr(e, "columns")}

    def _pre_names(self, e):
        return [p for p in self.theta_ if p.startswith(e.key + ".")]

    def _accel(self, x, v, u, ex, k, t, pre, effects=None):
        zero = np.zeros_like(x)
        e = self._errors(self._state(x, v, zero, u, ex, k, t), pre, effects)
        return (self._inertia @ e).T

    def linearised_eigenvalues(self) -> np.ndarray:
        """Eigenvalues (1/s) of the declared model (effects left out) linearised at the zero
        state with zero input: the state matrix [[0, I], [da/dx, da/dv]] by central differences.
        A rigid axis has one at 0 per position (an integrator); a stable joint's others have
        negative real parts; a positive real part is a model that falls over (a gravity term
        of the wrong sign, a negative stiffness or damping)."""
        if getattr(self, "_m", None) is None:
            self._check_fitted()
        n = len(self._m.positions)
        z, u, ex = self._zero_state(4 * n)
        x, v = z.copy(), z.copy()
        h = 1e-6
        for j in range(2 * n):
            (x if j < n else v)[2 * j, j % n] += h
            (x if j < n else v)[2 * j + 1, j % n] -= h
        acc = self._accel(x, v, u, ex, np.zeros(4 * n, dtype=int), np.zeros(4 * n),
                          self._zero_pre(4 * n), effects=())
        J = np.zeros((2 * n, 2 * n))
        J[:n, n:] = np.eye(n)
        J[n:, :] = ((acc[0::2] - acc[1::2]) / (2 * h)).T
        return np.linalg.eigvals(J)

    def stability(self) -> dict:
        """``{"stable", "eigenvalues", "max_real_part"}`` of :meth:`linearised_eigenvalues`;
        stable when no real part exceeds the differences' accuracy (1e-6 of the largest
        eigenvalue's magnitude): integrators (0) count as stable."""
        lam = self.linearised_eigenvalues()
        top = float(np.max(np.abs(lam))) if lam.size else 0.0
        worst = float(np.max(lam.real)) if lam.size else 0.0
        return {"stable": bool(worst <= 1e-6 * max(top, 1.0)), "max_real_part": worst,
                "eigenvalues": [[float(c.real), float(c.imag)] for c in lam]}

    def _choose_substeps(self) -> int:
        """h |lambda|max <= 0.5 for the base model linearised at the zero state.

        For the model kind's semi-implicit Euler this is a stability margin. For the windows'
        Runge-Kutta 4 (:meth:`windows`) the same bound is an accuracy rule: RK4's error per
        substep on a mode lambda is |h lambda|^5 / 120 of the state, so over one sample of n
        substeps it is at most n |h lambda|^5 / 120 <= |dt lambda| |h lambda|^4 / 120, which at
        |h lambda| <= 0.5 is 5e-4 |dt lambda|: three orders of magnitude below the change a
        half-sample timing shift makes in one sample (|dt lambda| / 2). The inputs are held
        over the sample in both (zero-order hold), which RK4 integrates without a timing error;
        semi-implicit Euler's own timing error is half a substep."""
        lam = float(np.max(np.abs(self.linearised_eigenvalues())))
        steps = max(1, int(np.ceil(float(self.dt) * lam / 0.5)))
        if steps > MAX_SUBSTEPS:
            raise ValueError(f"theta: the model's fastest mode ({lam:.3g} 1/s) needs {steps} "
                             f"substeps per sample (limit {MAX_SUBSTEPS}); not simulated")
        return steps

    # -- prediction ----------------------------------------------------------------------------
    def _inputs(self, U):
        """Inputs over one segment after the effects' input transforms (delays)."""
        m = self._m
        n = U.shape[0]
        s = {"t": np.arange(n) * float(self.dt)}
        s.update({name: U[:, i].astype(float) for i, name in enumerate(m.inputs)})
        for e in self.effects:
            s = e.transform_inputs(s, m)
        ni = len(m.inputs)
        ex = {c: U[:, ni + j].astype(float) for j, c in enumerate(self.extra_columns)}
        return {name: s[name] for name in m.inputs}, ex

    def _precomputed(self, U, Y) -> dict:
        """Whole-record effect columns from the measured segment (arm_coupling)."""
        wanted = [e for e in self.effects if hasattr(e, "columns")]
        if not wanted:
            return {}
        m = self._m
        if Y.shape[0] < 20:
            raise ValueError(f"Y: {wanted[0].key} needs at least 20 measured rows per segment")
        raw, extra = self._signals(m, U, Y)
        sig = m.prepare(np.arange(U.shape[0]) * float(self.dt), raw, self._filter(m), extra or None)
        s = apply_effects(m, sig, self.effects)
        return {e.key: e.columns(s) for e in wanted}

    def _rollout(self, U, Y, starts: np.ndarray, steps: int, path: bool,
                 x0=None, v0=None, pre=None, t_start: float = 0.0, integrator: str = "euler",
                 thetas=None) -> np.ndarray:
        """Integrate ``steps`` samples from the measured state at each row of ``starts`` (or
        from positions ``x0`` and velocities ``v0``, each (W, m)); returns the final positions
        (W, m), or every step's (steps, W, m) with ``path``. ``pre``: whole-record effect
        columns (default: from the measured ``Y``); ``t_start``: the time of row 0 (s).

        ``integrator``: "euler", the model kind's semi-implicit Euler with ``substeps_`` per
        sample (what a saved model and the firmware run), or "rk4", classical Runge-Kutta with
        the inputs held over the sample (zero-order hold, as the measured torque is) and the
        same substeps (the simulation windows; see :meth:`_choose_substeps` for the accuracy);
        its switching terms (a dry friction's sign, a direction test: :data:`.trace.SWITCHING`)
        are evaluated once per step at the step's start state and held over its four stages,
        as a firmware step holds them (evaluated at each stage, where the motion sticks the
        stages see -Fc, +Fc, -Fc, +Fc and RK4's weights 1, 2, 2, 1 cancel the friction); a
        velocity coordinate whose switching terms jump at its zero (a dry friction) stops at
        zero, holds there while the friction can hold it and breaks away in the direction of
        the net force otherwise in "rk4-stickslip" (stick-slip, :mod:`.stickslip`: a held
        sign alone carries the motion through zero and chatters where the motor sticks). Which
        of "rk4" and "rk4-stickslip" a record's windows use is decided on held-out data
        (:mod:`cdam_core.residual.selection`); "euler" (saved models, firmware) has no
        stick-slip.
        ``thetas``: (G, parameters) values in the order of ``theta_``, the W lanes split into G
        consecutive groups, each simulated with its own parameters (batched perturbations).

        The equations run compiled (``_core.greybox_rollout`` on the tape that
        :mod:`.trace` records from them) when the extension has it and the tape agrees with
        the numpy equations on the first states; otherwise in numpy, one step at a time."""
        if integrator not in INTEGRATORS:
            raise ValueError(f"integrator: expected one of {', '.join(INTEGRATORS)}, got "
                             f"{integrator!r}")
        u_all, ex_all = self._inputs(U)
        pre_all = self._precomputed(U, Y) if pre is None else pre
        dt = float(self.dt)
        x = Y[starts].astype(float) if x0 is None else np.array(x0, dtype=float)
        v = (Y[starts] - Y[starts - 1]) / dt if v0 is None else np.array(v0, dtype=float)
        names = list(self.theta_)
        if thetas is None:
            th = np.array([[self.theta_[p] for p in names]])
        else:
            th = np.atleast_2d(np.asarray(thetas, dtype=float))
            if th.shape[1] != len(names) or x.shape[0] % th.shape[0]:
                raise ValueError("thetas: expected (groups, parameters), lanes a multiple of groups")
        inv = self._inverses(th, names)
        sticky = self._sticky(u_all, ex_all, pre_all) if integrator == "rk4-stickslip" \
            else None
        fast = self._compiled(u_all, ex_all, pre_all)
        if fast is not None:
            out = self._rollout_compiled(fast, u_all, ex_all, pre_all, starts, steps, path, x, v,
                                         th, inv, t_start, integrator, sticky)
            if out is not None:
                return out
        per = x.shape[0] // th.shape[0]
        theta = {p: np.repeat(th[:, i], per) for i, p in enumerate(names)} \
            if th.shape[0] > 1 else None
        lane_inv = np.repeat(inv, per, axis=0)

        switches = tr.Switches()

        def acc(x, v, u, ex, k, t, stage=None):
            zero = np.zeros_like(x)
            if stage is not None:   # RK4: switching terms held from the step's first stage
                switches.record() if stage == 0 else switches.replay()
                x, v = tr.held(x, switches), tr.held(v, switches)
            e = self._errors(self._state(x, v, zero, u, ex, k, t), pre_all, theta=theta)
            e = np.asarray(e, dtype=float)
            if theta is None:
                return (self._inertia @ e).T
            return np.einsum("wij,jw->wi", lane_inv, e)

        h = dt / self.substeps_
        out = np.empty((steps,) + x.shape) if path else None
        for j in range(steps):
            k = starts + j
            u = {name: a[k] for name, a in u_all.items()}
            ex = {c: a[k] for c, a in ex_all.items()}
            t = t_start + k * dt
            for _ in range(self.substeps_):
                if integrator == "euler":
                    v = v + h * acc(x, v, u, ex, k, t)
                    x = x + h * v
                    continue
                zero = sticky[None, :] & (v == 0.0) if sticky is not None else v != v
                stuck = None
                if zero.any():      # coordinates at rest: stick or break away (stickslip)
                    def at(vv, x=x, u=u, ex=ex, k=k, t=t):
                        a_ = acc(x, vv, u, ex, k, t, 0)
                        return a_, switches.values
                    a1, held_values, stuck, side, limits = ss.start(at, v, zero)
                    switches.values = held_values
                else:
                    a1 = acc(x, v, u, ex, k, t, 0)
                    side = np.sign(v)
                x0_, v0_ = x, v
                x2, v2 = x + 0.5 * h * v, v + 0.5 * h * a1
                a2 = acc(x2, v2, u, ex, k, t, 1)
                if stuck is not None:
                    a2 = np.where(stuck, 0.0, a2)
                x3, v3 = x + 0.5 * h * v2, v + 0.5 * h * a2
                a3 = acc(x3, v3, u, ex, k, t, 2)
                if stuck is not None:
                    a3 = np.where(stuck, 0.0, a3)
                x4, v4 = x + h * v3, v + h * a3
                a4 = acc(x4, v4, u, ex, k, t, 3)
                if stuck is not None:
                    a4 = np.where(stuck, 0.0, a4)
                x = x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
                v = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
                if sticky is not None and sticky.any():
                    x, v, cross, left = ss.stop(x0_, v0_, x, v, side, sticky, h)
                    held_over = stuck if stuck is not None else np.zeros_like(cross)
                    if cross.any() or held_over.any():
                        def at_end(vv, x=x, u=u, ex=ex, k=k, t=t):
                            return acc(x, vv, u, ex, k, t, 0), switches.values
                        x, v = ss.finish(at_end, x, v, cross, left, held_over,
                                         limits if stuck is not None else None, h)
            if not np.all(np.isfinite(x)) or np.max(np.abs(x), initial=0.0) > 1e9:
                raise ValueError(f"prediction diverged at row {int(k[0]) + 1} of the segment")
            if path:
                out[j] = x
        return out if path else x

    def _sticky(self, u_all, ex_all, pre_all) -> np.ndarray:
        """(positions,) bool: the velocity coordinates a dry friction can stop (a switching
        term that jumps at their zero; :func:`.stickslip.sticky_coordinates`), from the numpy
        equations at the zero state, zero inputs and the series' first row; kept per model."""
        if "_sticky_" not in self.__dict__:
            m = self._m
            n = len(m.positions)
            sw = tr.Switches()
            k = np.zeros(2, dtype=int)

            def values(v):
                sw.record()
                x = np.zeros((2, n))
                u = {name: np.zeros(2) for name in u_all}
                ex = {c: np.zeros(2) for c in ex_all}
                self._errors(self._state(tr.held(x, sw), tr.held(v, sw), np.zeros((2, n)), u,
                                         ex, k, np.zeros(2)), pre_all)
                return sw.values
            self.__dict__["_sticky_"] = ss.sticky_coordinates(values, n)
        return self.__dict__["_sticky_"]

    def _inverses(self, th: np.ndarray, names: list) -> np.ndarray:
        """The inertia inverse of each parameter group (G, m, m)."""
        if th.shape[0] == 1 and np.array_equal(th[0], [self.theta_[p] for p in names]):
            return self._inertia[None].copy()
        keep = dict(self.theta_)
        out = []
        try:
            for row in th:
                self.theta_ = dict(zip(names, map(float, row)))
                out.append(self._inertia_matrix())
        finally:
            self.theta_ = keep
        return np.array(out)

    # -- the compiled path ----------------------------------------------------------------------
    def _series_layout(self, u_all, ex_all, pre_all) -> tuple:
        return (tuple(u_all), tuple(ex_all),
                tuple((key, tuple(cols)) for key, cols in pre_all.items()))

    def _compiled(self, u_all, ex_all, pre_all):
        """The tape of the model's accelerations for this series layout, or None (no extension
        function, or the equations cannot be traced)."""
        if not self.compiled:
            return None
        try:
            from cdam_core import _core
        except ImportError:
            return None
        if not hasattr(_core, "greybox_rollout") or getattr(_core, "GREYBOX_TAPE_OPS", 0) != \
                len(tr.OPS) or not getattr(_core, "GREYBOX_STICK_SLIP", 0):
            return None
        layout = self._series_layout(u_all, ex_all, pre_all)
        cache = self.__dict__.setdefault("_tapes", {})
        if layout not in cache:
            try:
                tape, outs = self._trace(u_all, ex_all, pre_all)
                cache[layout] = (tape.arrays(), outs, _core.greybox_rollout, {"ok": None})
            except (tr.TraceError, KeyError, TypeError):
                cache[layout] = None
        return cache[layout]

    def _trace(self, u_all, ex_all, pre_all):
        """The tape of the equation errors (:mod:`.trace`) and its output nodes; the series
        columns are the inputs, the external columns, then the whole-record effect columns."""
        m = self._m
        tape = tr.Tape()
        col = iter(range(10 ** 9))
        u = {name: tape.leaf("S", next(col)) for name in u_all}
        ex = {c: tape.leaf("S", next(col)) for c in ex_all}
        pre_at = {key: {n: tape.leaf("S", next(col)) for n in cols}
                  for key, cols in pre_all.items()}
        s = {"t": tape.leaf("T", 0), "extra": ex, "k": None, "dt": float(self.dt)}
        s.update(u)
        for j, p in enumerate(m.positions):
            s[p], s[p + "_d"], s[p + "_dd"] = tape.leaf("X", j), tape.leaf("V", j), 0.0
        s = m.augment(s)
        eqs = self._terms(s, pre_at)
        index = {p: i for i, p in enumerate(self.theta_)}
        outs = []
        for y, cols in eqs.values():
            r = tr._as_sym(tape, y)
            for p, c in cols.items():
                r = r - tape.leaf("P", index[p]) * tr._as_sym(tape, c)
            outs.append(r.i)
        if len(outs) != len(m.positions):
            raise tr.TraceError("equations and positions differ in number")
        return tape, np.array(outs, dtype=np.int32)

    def _rollout_compiled(self, fast, u_all, ex_all, pre_all, starts, steps, path, x, v, th,
                          inv, t_start, integrator, sticky=None):
        (op, a, b, c), outs, run, state = fast
        cols = list(u_all.values()) + list(ex_all.values()) + \
            [col for cols in pre_all.values() for col in cols.values()]
        series = np.column_stack([np.asarray(cc, dtype=float) for cc in cols])
        st = np.asarray(starts, dtype=np.int64)
        if st.size != x.shape[0]:
            st = np.broadcast_to(st, (x.shape[0],)).copy()
        per = x.shape[0] // th.shape[0]
        if state["ok"] is None:   # the tape against the numpy equations on the first states
            lanes = np.arange(min(x.shape[0], 8))
            g = lanes // per
            # one Euler step of length 1 from (x, v) gives x + v + a: the acceleration itself
            x1, _ = run(op, a, b, c, outs, series, th[g], inv[g], x[lanes], v[lanes], st[lanes],
                        1, 1, False, 1.0, float(t_start), False)
            got = x1 - x[lanes] - v[lanes]
            names = list(self.theta_)
            theta = {p: th[g, i] for i, p in enumerate(names)}
            u = {name: col[st[lanes]] for name, col in u_all.items()}
            ex = {cc: col[st[lanes]] for cc, col in ex_all.items()}
            keep_dt = self.dt
            try:
                self.dt = 1.0    # the tape's time leaf and the check share the step
                e = self._errors(self._state(x[lanes], v[lanes], np.zeros_like(x[lanes]), u, ex,
                                             st[lanes], t_start + st[lanes] * 1.0),
                                 pre_all, theta=theta)
            finally:
                self.dt = keep_dt
            want = np.einsum("wij,jw->wi", inv[g], e)
            tol = 1e-8 * (np.abs(want) + np.abs(x[lanes]) + np.abs(v[lanes])) + 1e-300
            state["ok"] = bool(np.all(np.isfinite(want)) and np.all(np.abs(got - want) <= tol))
        if not state["ok"]:
            return None
        P, diverged = run(op, a, b, c, outs, series, th, inv, x, v, st, int(steps),
                          int(self.substeps_), integrator != "euler", float(self.dt),
                          float(t_start), bool(path),
                          np.zeros(0, dtype=np.int32) if sticky is None
                          else sticky.astype(np.int32))
        if diverged >= 0:
            raise ValueError(f"prediction diverged at row {int(diverged)} of the segment")
        return P

    @property
    def declared_model(self):
        """The declared model (a ``GreyBoxModel``) of the fitted grey box."""
        self._check_fitted()
        return self._m

    @property
    def inertia(self) -> np.ndarray:
        """How the equation errors map to accelerations (a copy; see ``_accel``)."""
        self._check_fitted()
        return np.array(self._inertia, dtype=np.float64)

    def set_parameters(self, values: dict) -> "GreyBox":
        """Replace estimated parameter values (output-error refinement); returns self."""
        self._check_fitted()
        for k, v in values.items():
            if k not in self.theta_:
                raise ValueError(f"values: {k!r} is not a parameter of the model")
            if not np.isfinite(v):
                raise ValueError(f"values: {k} is not finite")
            self.theta_[k] = float(v)
        self._inertia = self._inertia_matrix()
        return self

    def windows(self, U, Y, starts, steps: int, x0=None, v0=None, integrator: str = "euler",
                thetas=None) -> np.ndarray:
        """Simulate ``steps`` samples from the measured state at each row of ``starts`` (one
        segment ``U``, ``Y``: multiple shooting windows), or from the given positions ``x0``
        and velocities ``v0`` (each (len(starts), outputs)); returns the simulated positions
        (steps, len(starts), outputs) of rows ``start + 1 .. start + steps``.

        ``integrator``: "euler" (default: the model kind's semi-implicit Euler, what a saved
        model and the firmware run; its timing error is half a substep), "rk4" (Runge-Kutta
        4 with the inputs held over the sample: a window's integration error far below the
        half-sample effects its scores may decide on, see :meth:`_choose_substeps`; a dry
        friction's sign held over each step) or "rk4-stickslip" (the same, a dry friction
        sticking and slipping: :meth:`_rollout`).
        ``thetas``: (G, parameters) in the order of :meth:`parameters`; the windows are split
        into G consecutive groups, each simulated with its own parameter values (a batched
        finite-difference Jacobian).
        """
        self._check_fitted()
        U, Y = as_2d(U, "U"), as_2d(Y, "Y")
        if U.shape != (Y.shape[0], self.n_inputs_) or Y.shape[1] != self.n_outputs_:
            raise ValueError(f"U, Y: expected ({Y.shape[0]}, {self.n_inputs_}) and "
                             f"(N, {self.n_outputs_}), got {U.shape} and {Y.shape}")
        starts = np.asarray(starts, dtype=int)
        if starts.ndim != 1 or starts.size == 0:
            raise ValueError("starts: expected a non-empty list of rows")
        steps = int(steps)
        if steps < 1 or starts.min() < self.t0 - 1 or starts.max() + steps >= Y.shape[0]:
            raise ValueError(f"starts/steps: windows must lie in rows {self.t0 - 1}.."
                             f"{Y.shape[0] - 1} of the segment")
        W = (starts.size, self.n_outputs_)
        for name, a in (("x0", x0), ("v0", v0)):
            if a is not None and (np.shape(a) != W or not np.all(np.isfinite(a))):
                raise ValueError(f"{name}: expected finite values of shape {W}")
        if thetas is not None:
            th = np.asarray(thetas, dtype=float)
            if (th.ndim != 2 or th.shape[1] != len(self.theta_) or th.shape[0] < 1
                    or starts.size % th.shape[0] or not np.all(np.isfinite(th))):
                raise ValueError(f"thetas: expected finite (groups, {len(self.theta_)}) values "
                                 f"with the {starts.size} windows a multiple of the groups")
        return self._rollout(U, Y, starts, steps, True, x0, v0, integrator=integrator,
                             thetas=thetas)

    def _one_step(self, U, Y):
        return self._k_step(U, Y, 1)[self.t0:]

    def _k_step(self, U, Y, k):
        P = Y.astype(float).copy()
        first = self.t0 + k - 1
        if Y.shape[0] > first:
            targets = np.arange(first, Y.shape[0])
            P[targets] = self._rollout(U, Y, targets - k, k, path=False)
        return P

    def _free_run_segment(self, U, Y):
        n = Y.shape[0]
        path = self._rollout(U, Y, np.array([self.t0 - 1]), n - self.t0, path=True)
        return path[:, 0, :]

    def parameters(self) -> dict:
        self._check_fitted()
        return {p: (v, self.std_.get(p)) for p, v in self.theta_.items()}

    # -- file ----------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        self._check_fitted()
        names = list(self.theta_)
        return {"declared": self.declared, "dt": float(self.dt),
                "n_inputs": self.n_inputs_, "n_outputs": self.n_outputs_,
                "fixed": dict(self.fixed), "extra_columns": list(self.extra_columns),
                "filter": {"cutoff_hz": float(self._filter(self._m).cutoff_hz),
                           "order": int(self.filter_order),
                           **({"cutoff_per_signal_hz": {k: float(v) for k, v in
                                                        self.cutoff_hz.items()}}
                              if isinstance(self.cutoff_hz, dict) else {})},
                "effects": [_effect_to_dict(e) for e in self.effects],
                "parameters": {"names": names, "values": [self.theta_[p] for p in names],
                               "std": [self.std_.get(p) for p in names],
                               "estimated": list(self.estimated_)},
                "substeps": int(self.substeps_)}

    @classmethod
    def from_dict(cls, d: dict) -> "GreyBox":
        if d["declared"] not in MODEL_NAMES:
            raise ValueError(f"model.declared: unknown model {d['declared']!r}")
        effects = [_effect_from_dict(e, f"model.effects[{j}]") for j, e in enumerate(d["effects"])]
        filt = d["filter"]
        cut = filt.get("cutoff_per_signal_hz") or filt["cutoff_hz"]
        g = cls(d["declared"], float(d["dt"]), effects, d["fixed"], cut,
                int(filt["order"]), d["extra_columns"])
        try:
            m = g._structure()
        except ValueError as exc:
            raise ValueError(f"model.{exc}") from None
        par = d["parameters"]
        names, values, std = par["names"], par["values"], par["std"]
        if not (len(names) == len(values) == len(std)):
            raise ValueError("model.parameters: names, values and std differ in length")
        if len(set(names)) != len(names):
            raise ValueError("model.parameters.names: repeated name")
        expected = _parameter_names(m, effects, g)
        late = sorted((set(m.optional_terms) & expected) - set(names))
        if late:
            # a file written before these declared terms existed (the joint's Gc cos q and
            # constants, session 15): the model it holds is the one with them at 0
            fixed = {**d["fixed"], **{p: 0.0 for p in late}}
            g2 = cls(d["declared"], float(d["dt"]), effects, fixed, cut, int(filt["order"]),
                     d["extra_columns"])
            m2 = g2._structure()
            if set(names) | set(late) == _parameter_names(m2, effects, g2):
                g, m = g2, m2
                names = list(names) + late
                values, std = list(values) + [0.0] * len(late), list(std) + [None] * len(late)
                expected = set(names)
        if set(names) != expected:
            extra = sorted(set(names) - expected)
            missing = sorted(expected - set(names))
            raise ValueError(f"model.parameters.names: do not match the model and its effects "
                             f"(unexpected {extra}, missing {missing})")
        for j, v in enumerate(values):
            if not np.isfinite(v):
                raise ValueError(f"model.parameters.values[{j}]: not a finite number")
        if d["n_inputs"] != len(m.inputs) + len(g.extra_columns) or d["n_outputs"] != len(m.positions):
            raise ValueError("model.n_inputs: does not match the declared model and extra columns")
        estimated = par["estimated"]
        if not set(estimated) <= set(names):
            raise ValueError("model.parameters.estimated: names a parameter not in names")
        g._set(m, dict(zip(names, values)), dict(zip(names, std)), estimated,
               d["n_inputs"], d["n_outputs"], substeps=d["substeps"])
        return g


def _parameter_names(m, effects, g: GreyBox) -> set:
    """Every parameter the model with ``effects`` has (its equations' columns), from a tiny
    synthetic record: what a file must hold, no more and no less."""
    n = 64
    t = np.arange(n) * float(g.dt)
    raw = {name: np.zeros(n) for name in m.inputs}
    raw.update({p: np.zeros(n) for p in m.positions})
    sig = {"t": t, "dt": float(g.dt), "extra": {c: np.zeros(n) for c in g.extra_columns}}
    sig.update(raw)
    for p in m.positions:
        sig[p + "_raw"] = raw[p]
        sig[p + "_d"] = np.zeros(n)
        sig[p + "_dd"] = np.zeros(n)
        for suffix in ("_dj", "_ddj"):
            sig[p + suffix] = np.zeros(n)
    sig = m.augment(sig)
    _, eqs = design(m, sig, effects)
    names = set(m.fixed)
    for _, cols in eqs.values():
        names |= set(cols)
    return names
