"""Stick-slip of a dry friction in the grey-box RK4 rollout (the numpy twin of the compiled one).

A force that jumps where a velocity coordinate crosses zero (a dry friction ``Fc sign(v)``, an
asymmetric friction's direction test ``v > 0``) cannot be integrated as written: a step that
holds the friction's sign carries the motion through zero and the next step pushes it back, so
a motor that physically sticks chatters around zero speed and its simulated dry friction acts
like part viscous, part nothing. The physics: a dry friction cannot reverse the motion, and at
rest it holds the coordinate as long as the rest of the force stays inside its level.

One mechanism, on the equations as written (the same for every model and effect):

- *Which coordinates.* A velocity coordinate j *sticks* when the model's switching terms
  (:data:`.trace.SWITCHING`) differ between its one-sided limits v_j -> 0+ and v_j -> 0- with
  the other velocities away from zero (:func:`sticky_coordinates`): a force that jumps at
  v_j = 0. A switching term of a relative velocity (v_j - v_k) does not make j stick.
- *At rest* (v_j exactly 0 at a step's start): the accelerations are evaluated with v_j at its
  two one-sided limits (v_j = +-:data:`LIMIT`, a speed so small that the continuous terms it
  enters stay below double precision of every other term: only the switching terms see its
  sign), a+ and
  a-. If a+_j <= 0 <= a-_j the friction can hold the coordinate (Filippov's convex combination
  of the two sides' fields tangent to v_j = 0): the coordinate stays at rest over the step
  (its velocity and acceleration 0 at every stage) and the rest of the system moves under the
  switching terms interpolated between the two sides with the same weights. Otherwise it
  breaks away on the side its net force points to (the sign of a+_j + a-_j, ties to +), the
  switching terms held from that side.
- *Moving*: the step is the held-switch RK4 step; if the velocity ends on the other side of
  zero from the step's direction, the motion stopped within the step: the velocity is set to
  0 and the position to where a constant deceleration over the step stops it
  (x0 + h v0^2 / (2 (v0 - v1)), at t* = h v0 / (v0 - v1)); the rest of the step, h - t*, is
  spent at rest or, where the rule above breaks the coordinate away there, at that side's
  acceleration a: v = a (h - t*), x = x_stop + a (h - t*)^2 / 2 (a reversal through zero
  otherwise loses up to a step, a velocity error of a h: measured on the README's joint, the
  true parameters' held-out window error was 2.1e-5 without this rest of the step, 6.9e-7
  with it, 7.6e-7 with the plain sign held over the step).
- *Held over a step*: at its end the rule is applied again; a coordinate the end state no
  longer holds broke away within the step, where its net force crossed the level (linear
  between the step's ends), so the motion depends continuously on the parameters
  (:func:`finish`).

Several coordinates at rest in one lane are tested each against the others' + limits (exact
when the inertia matrix does not couple them, as for a joint's motor and link; a coupled
multi-contact stick would need a complementarity solve). The model kind's semi-implicit Euler
(saved models, firmware) does not use this; it is the "rk4-stickslip" rollout of the windows
(output error, IDIM-IV's auxiliary model, held-out validation), which a record's analysis
takes instead of "rk4" (the sign held over each step) only where the chosen model predicts
held-out windows better with it (:func:`cdam_core.residual.selection.choose_stick_slip`:
simulated in every window of every decision, session 9, it lost a friction finding and
doubled a friction error on other seeds of the README's joint record).
"""
from __future__ import annotations

import numpy as np

__all__ = ["LIMIT", "sticky_coordinates", "start", "stop", "finish"]

# The one-sided limit of a velocity at rest: any continuous term it enters (Dm v, v |v|) changes
# by ~1e-150 of its coefficient, far below double precision of the forces; its square (1e-300)
# is still a normal double, so a sign of v |v| sees it too. Shared with cpp/bindings/greybox.cpp.
LIMIT = 1e-150


def _float(a):
    return np.asarray(a, dtype=float)


def _lanes(w, like):
    """``w`` (W,) broadcast along the lanes (first) axis of ``like``."""
    return w.reshape((-1,) + (1,) * (np.ndim(like) - 1))


def sticky_coordinates(switch_values, n: int) -> np.ndarray:
    """(n,) bool: coordinate j sticks when ``switch_values(v)`` (the switching terms' values,
    a list of arrays over lanes, at velocities v (lanes, n)) differ between v_j = +LIMIT and
    v_j = -LIMIT with every other velocity at 1 (away from zero)."""
    out = np.zeros(n, dtype=bool)
    for j in range(n):
        v = np.ones((2, n))
        v[0, j], v[1, j] = LIMIT, -LIMIT
        for s in switch_values(v):
            s = _float(s)
            if s.ndim and s.shape[0] == 2 and np.any(s[0] != s[1]):
                out[j] = True
                break
    return out


def start(accel, v: np.ndarray, zero: np.ndarray):
    """The first stage of a step with coordinates at rest (``zero``: (W, n), v == 0 there).

    ``accel(v)`` returns (accelerations (W, n), switching values (list)) at the step's start
    positions and velocities ``v``. Returns (a1, switching values to hold over the step, stuck
    (W, n) bool, side (W, n): +1 / -1 the direction of the step's motion, 0 stuck, the one-sided
    accelerations (a+, a-) of the coordinates at rest, each (W, n))."""
    vp = np.where(zero, LIMIT, v)
    ap, sp = accel(vp)
    a1, vals = ap, list(sp)
    stuck = np.zeros(zero.shape, dtype=bool)
    side = np.sign(v)
    lim_p, lim_m = np.where(zero, ap, 0.0), np.zeros(zero.shape)
    for j in np.flatnonzero(zero.any(axis=0)):
        vm = vp.copy()
        vm[zero[:, j], j] = -LIMIT
        am, sm = accel(vm)
        apj, amj = ap[:, j], am[:, j]
        st = zero[:, j] & (apj <= 0.0) & (amj >= 0.0)
        gap = amj - apj
        lam = np.where(gap > 0.0, amj / np.where(gap > 0.0, gap, 1.0), 0.5)   # + side's weight
        plus = apj + amj >= 0.0
        w = np.where(zero[:, j], np.where(st, 1.0 - lam, np.where(plus, 0.0, 1.0)), 0.0)
        a1 = a1 + w[:, None] * (am - ap)
        vals = [val + _lanes(w, val) * (_float(m) - _float(p))
                for val, m, p in zip(vals, sm, sp)]
        stuck[:, j] = st
        lim_m[:, j] = np.where(zero[:, j], amj, 0.0)
        side[:, j] = np.where(zero[:, j], np.where(st, 0.0, np.where(plus, 1.0, -1.0)), side[:, j])
    return np.where(stuck, 0.0, a1), vals, stuck, side, (lim_p, lim_m)


def stop(x0, v0, x, v, side, sticky, h: float):
    """The end of a step: a sticking coordinate whose velocity ended against the step's
    direction ``side`` stopped within it (module doc): its velocity is set to 0 and its
    position to the stop. Returns (x, v, crossed (W, n) bool, the time left in the step after
    the stop (W, n))."""
    cross = sticky[None, :] & (side * v < 0.0)
    if not cross.any():
        return x, v, cross, np.zeros(v.shape)
    gap = np.where(cross, v0 - v, 1.0)
    x = np.where(cross, x0 + 0.5 * h * v0 * v0 / gap, x)
    left = np.where(cross, -h * v / gap, 0.0)
    return x, np.where(cross, 0.0, v), cross, left


def finish(accel, x, v, cross, left, stuck, limits, h: float):
    """The end of a step at the end state, by :func:`start`'s rule: a coordinate that stopped
    within the step (``cross``, ``left`` the time after the stop) spends the rest of it at rest
    or at its broken-away side's acceleration a (v = a left, x += a left^2 / 2); a coordinate
    held over the step (``stuck``, with the step's start ``limits``) that the end state no
    longer holds broke away within it: where that side's acceleration, a0 at the start and a
    at the end, crossed zero (linearly), after which it rose to a: v = a tau / 2,
    x += a tau^2 / 6, tau = h a / (a - a0). Breaking away at the step's end instead would
    move the motion by a whole step as a parameter crosses the level (a jump in the windows
    that output error differentiates). Returns (x, v)."""
    a, _, held, side, _ = start(accel, v, cross | stuck)
    go = stuck & ~held
    if limits is None:
        limits = (np.zeros(v.shape), np.zeros(v.shape))
    a0 = np.where(side > 0.0, limits[0], limits[1])
    tau = np.where(go, h * a / np.where(go, a - a0, 1.0), 0.0)
    x = np.where(cross, x + 0.5 * a * left * left, np.where(go, x + a * tau * tau / 6.0, x))
    v = np.where(cross, a * left, np.where(go, 0.5 * a * tau, v))
    return x, v
