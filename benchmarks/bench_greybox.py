"""Benchmark of [speed] issue 23 item 4: the grey-box rollouts of the residual loop, compiled
(the model's numpy equations traced once into a tape, ``_core.greybox_rollout``) against the
numpy path they replace (one Python step per sample, every window at once), in the same process,
on EMPS (DATA_EMPS, the final model: rigid axis + Coulomb + asymmetric friction):

- ``greybox_free_run``: the model kind's free run over DATA_EMPS (24,841 samples, one lane):
  the path of ``cdam residual``'s free runs and of the benchmark protocol's score.
- ``greybox_windows``: the held-out validation windows (by RK4), each window's initial state
  perturbed (3 lanes per window), as ``BlockedCV._shooting`` runs them.
- ``greybox_oe_jacobian``: one output-error Jacobian over the training windows: the base
  point and one group of lanes per parameter in one rollout, against the numpy path running
  them one column after the other (what scipy's finite differences did).

"ratio" is numpy over compiled; the numpy path is the fairest reference we have (already
vectorised over windows; what remains is sequential in time). Thread CPU time, best of N."""
from __future__ import annotations

import time

import numpy as np

from timing import best_of


def _emps_model():
    from cdam_core.models.greybox.augmented import GreyBox
    from cdam_core.models.greybox.effects import AsymmetricFriction, CoulombFriction
    from cdam_core.record.realdata.emps import load_emps
    d = load_emps("DATA_EMPS")
    U, Y = d["force"][:, None], d["qm"][:, None]
    g = GreyBox("rigid_axis", float(np.mean(np.diff(d["t"]))),
                [CoulombFriction("tau"), AsymmetricFriction("tau")], cutoff_hz=400.0,
                fixed={"G": 0.0, "Gc": 0.0})   # EMPS is a linear axis
    g.fit(U, Y)
    return g, U, Y


def _numpy_twin(g):
    from cdam_core.models.greybox.augmented import GreyBox
    h = GreyBox.from_dict(g.to_dict())
    h.compiled = False
    return h


def _entry(fast, slow, repeats_fast=5, repeats_slow=1, what="") -> dict:
    a = fast()
    b = slow()
    diff = float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
    tf = best_of(fast, repeats_fast, time.thread_time)
    ts = best_of(slow, repeats_slow, time.thread_time)
    return {"seconds": tf, "reference_seconds": ts, "ratio": ts / tf,
            "reference": f"the numpy rollout ({what})", "max_abs_difference": diff}


def free_run() -> dict:
    g, U, Y = _emps_model()
    h = _numpy_twin(g)
    out = _entry(lambda: g.predict(U, Y, mode="free_run"),
                 lambda: h.predict(U, Y, mode="free_run"), what="one Python step per sample")
    out.update(samples=int(Y.shape[0]), substeps=int(g.substeps_))
    return out


def _windows_case():
    """The EMPS model, its numpy twin and the validation windows of ``cdam residual`` on
    DATA_EMPS (horizon 621 samples, the motion's correlation time), 3 lanes per window."""
    g, U, Y = _emps_model()
    H = 621
    starts = np.arange(50, Y.shape[0] - H - 50, H)
    return g, _numpy_twin(g), U, Y, starts, np.tile(starts, 3), H


def windows() -> dict:
    g, h, U, Y, starts, lanes, H = _windows_case()
    out = _entry(lambda: g.windows(U, Y, lanes, H, integrator="rk4"),
                 lambda: h.windows(U, Y, lanes, H, integrator="rk4"),
                 what="RK4, every window at once")
    out.update(windows=int(starts.size), lanes=int(lanes.size), horizon=H)
    return out


def oe_jacobian() -> dict:
    g, h, U, Y, starts, lanes, H = _windows_case()
    names = list(g.theta_)
    base = np.array([g.theta_[p] for p in names])
    est = [names.index(p) for p in g.estimated_]
    TH = np.tile(base, (len(est) + 1, 1))
    for j, i in enumerate(est):
        TH[j + 1, i] *= 1 + 1e-4

    def batched():
        return g.windows(U, Y, np.tile(lanes, TH.shape[0]), H, thetas=TH)

    def columns():
        out = []
        for row in TH:
            h.set_parameters(dict(zip(names, row)))
            out.append(h.windows(U, Y, lanes, H))
        return np.concatenate(out, axis=1)
    res = _entry(batched, columns, what="one rollout per Jacobian column")
    res.update(parameters=len(est), lanes=int(lanes.size * TH.shape[0]))
    return res


def residual_flight() -> dict:
    """``cdam residual``'s analysis (structure search, held-out tests, free runs) of the README's
    hidden-effect flight at 20 s (``cdam simulate --experiment both --duration 20 --seed 1
    --effect thrust_loss:c=0.003``, read back from its CSV as the command reads it), BLAS on one
    thread as the command runs it. No reference in the same process: the fits before the
    per-record caches ([speed] 23.4) are not kept; their time is the README's separate runs."""
    import tempfile
    from pathlib import Path
    from threadpoolctl import threadpool_limits
    from cdam_core.models.greybox.registry import get_model
    from cdam_core.record.dataset import read_dataset
    from cdam_core.residual import analyse
    from cdam_core.sim import simulate_flight, write_flight
    m = get_model("aerial_manipulator")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f.csv"
        write_flight(path, simulate_flight("both", duration=20.0, seed=1,
                                           effects=["thrust_loss:c=0.003"]))
        ds = read_dataset(path)
    sig = {k: ds.column(c) for k, c in m.defaults.items()}
    found = []

    def run():
        with threadpool_limits(1, user_api="blas"):
            sel = analyse("aerial_manipulator", ds.t, sig)
        found[:] = [s.candidate.effect.key for s in sel.steps]   # after the backward pass
    t = best_of(run, 2, time.thread_time)
    return {"seconds": t, "ratio": None, "samples": len(ds),
            "reference": "none in the same process (README: separate runs before and after)",
            "effects_found": ", ".join(found)}


BENCHMARKS = {"greybox_free_run": free_run, "greybox_windows": windows,
              "greybox_oe_jacobian": oe_jacobian, "residual_flight": residual_flight}

if __name__ == "__main__":
    for k, fn in BENCHMARKS.items():
        print(k, fn())
