"""Example reports for the README.

``python -m cdam_core.cli.example emps OUT_DIR`` writes the EMPS residual report
(DATA_EMPS fitted with ``rigid_axis``: Coulomb then asymmetric friction found; free-run errors
on DATA_EMPS_PULSES) into ``OUT_DIR`` (index.md, residual.json, PNG figures), and a second
report for DATA_EMPS_PULSES alone (its residual's lines tested against the model's terms) into
``OUT_DIR/pulses``.
``python -m cdam_core.cli.example flight OUT_DIR`` writes the report of a simulated
flight with a hidden thrust loss (``cdam simulate`` + ``aerial_manipulator``).
"""
from __future__ import annotations

import argparse
import sys
from contextlib import nullcontext
from pathlib import Path


def emps_report(out_dir, ticker=None) -> Path:
    """Write the EMPS example report into ``out_dir``; returns the path of index.md.
    ``ticker(what)``: a context manager shown while a long step runs (none by default)."""
    from cdam_core.record.realdata.emps import EMPS_UNITS, load_emps
    from cdam_core.report.residual import write_report
    from cdam_core.residual.analyse import analyse
    ticker = ticker or (lambda what: nullcontext())
    d, p = load_emps("DATA_EMPS"), load_emps("DATA_EMPS_PULSES")
    with ticker("the residual loop on DATA_EMPS (structure, estimator, free runs)"):
        sel = analyse("rigid_axis", d["t"], {"tau": d["force"], "q": d["qm"]},
                      validation=(p["t"], {"tau": p["force"], "q": p["qm"]}), units=EMPS_UNITS)
    out = write_report(sel, out_dir, title="EMPS (DATA_EMPS, free run on DATA_EMPS_PULSES)",
                       source="EMPS benchmark (Janot, Gautier, Brunot 2019): force = gtau * vir, "
                              "output qm; free-run errors on DATA_EMPS_PULSES",
                       units=EMPS_UNITS)
    _emps_benchmark(sel, p, Path(out_dir), ticker)
    with ticker("the residual loop on DATA_EMPS_PULSES"):
        selp = analyse("rigid_axis", p["t"], {"tau": p["force"], "q": p["qm"]}, free_run=False,
                       units=EMPS_UNITS)
    write_report(selp, Path(out_dir) / "pulses", title="EMPS DATA_EMPS_PULSES",
                 source="EMPS benchmark, DATA_EMPS_PULSES (pulses inside vir)", units=EMPS_UNITS)
    return out


def _emps_benchmark(sel, p: dict, out_dir: Path, ticker) -> None:
    """nonlinearbenchmark.org's EMPS protocol: the declared and final models (fitted on
    DATA_EMPS) simulated on DATA_EMPS_PULSES; printed beside the published results and written
    to ``benchmark.json``."""
    from cdam_core.base.jsonio import write_json_atomic
    from cdam_core.evaluate.simulation import EMPS_PROTOCOL, EMPS_PUBLISHED
    from cdam_core.residual.benchmark import protocol_scores
    with ticker("the benchmark protocol: the models and two baselines simulated"):
        sc = protocol_scores(sel, {"t": p["t"], "tau": p["force"], "q": p["qm"]},
                             EMPS_PROTOCOL["n_init"], EMPS_PROTOCOL["scale"])
        rows = [(f"cdam {k} model ({', '.join(e.key for e in f.effects) or 'no effects'})",
                 v.rmse[0] if v.status == "ok" else None, v.reason or "this run")
                for (k, v), f in zip(sc.items(), (sel.declared, sel.final))]
        rows.append(_arx_baseline(p))
        rows += _simulation_error_baseline(sel, p)
        rows.append(_lti_baseline())
    rows += list(EMPS_PUBLISHED)
    print(f"EMPS benchmark (train DATA_EMPS, test DATA_EMPS_PULSES, first "
          f"{EMPS_PROTOCOL['n_init']} samples of qm given, simulation RMSE of qm):")
    for name, v, src in rows:
        print(f"  {name:<60} {'n/a' if v is None else f'{v:7.2f}'} mm   {src}")
    write_json_atomic(out_dir / "benchmark.json",
                      {"protocol": EMPS_PROTOCOL,
                       "results": [{"model": n, "rmse_mm": v, "source": s} for n, v, s in rows]})


def _simulation_error_baseline(sel, p: dict) -> list:
    """The physical baseline fitted by simulation error: the published model's structure
    (M, Fv, Fc, offset) by IDIM-LS on DATA_EMPS, then refined by output error on all of
    DATA_EMPS, by multiple shooting (the loop's windows) and by simulation error over the
    whole record (residual.output_error.simulation_refine), each simulated under the
    protocol."""
    import numpy as np
    from cdam_core.evaluate.simulation import EMPS_PROTOCOL, simulation_score
    from cdam_core.models.greybox.effects import CoulombFriction
    from cdam_core.models.greybox.estimation import fit
    from cdam_core.residual.benchmark import greybox_of
    from cdam_core.residual.validation import BlockedCV
    m, sig = sel.declared.model, sel.declared.signals
    f = fit(m, sig, (CoulombFriction("tau"),), sel.settings["trim"])
    cv = BlockedCV(m, sig, sel.settings["trim"])   # RK4 windows, the sign held over a step
    rows = []
    for how, refine in ((f"multiple shooting, {cv.horizon * cv.dt:.2f} s windows", cv.refine),
                        ("whole record, its initial state fitted", cv.simulate_refine)):
        g = greybox_of(f, cv.dt)
        refine(g, f, cv.inputs(f.effects), np.ones(cv.Y.shape[0], bool))
        sc = simulation_score(g, p["force"][:, None], p["qm"][:, None],
                              EMPS_PROTOCOL["n_init"], EMPS_PROTOCOL["scale"])
        rows.append((f"M, Fv, Fc, offset fitted by simulation error on DATA_EMPS ({how})",
                     sc.rmse[0] if sc.status == "ok" else None, sc.reason or "this run"))
    return rows


def _lti_baseline() -> tuple:
    """The linear baseline fitted by simulation error (evaluate.lti_oe): a transfer function
    from vir to qm, its order chosen on four held-out blocks of DATA_EMPS (the fewest
    parameters within one standard error of the best held-out mean)."""
    from cdam_core.evaluate.lti_oe import choose, emps_lti_baseline
    m, te, table = emps_lti_baseline(log=lambda *a: None)
    v = choose(table)[0]
    return (f"LTI output error, order {m.n}{' + input offset' if m.offset else ''} chosen on "
            f"held-out blocks of DATA_EMPS (validation {v:.1f} mm)", te, "this run")


def _arx_baseline(p: dict) -> tuple:
    """The linear baseline under the same protocol: a least-squares ARX(na, nb, 1) from force
    to qm, orders (1..3 each) chosen by the protocol's simulation error on the last quarter of
    DATA_EMPS after fitting on the first three quarters, then refitted on all of DATA_EMPS."""
    import numpy as np
    from cdam_core.evaluate.simulation import EMPS_PROTOCOL, simulation_score
    from cdam_core.models import ArxModel
    from cdam_core.record.realdata.emps import load_emps
    d = load_emps("DATA_EMPS")
    U, Y = d["force"][:, None], d["qm"][:, None]
    cut = int(0.75 * len(Y))
    n0, mm = EMPS_PROTOCOL["n_init"], EMPS_PROTOCOL["scale"]
    best = None
    for na in (1, 2, 3):
        for nb in (1, 2, 3):
            sc = simulation_score(ArxModel((na, nb, 1)).fit(U[:cut], Y[:cut]), U[cut:], Y[cut:],
                                  n0, mm)
            v = sc.rmse[0] if sc.status == "ok" else np.inf
            if best is None or v < best[0]:
                best = (v, na, nb)
    sc = simulation_score(ArxModel((best[1], best[2], 1)).fit(U, Y), p["force"], p["qm"], n0, mm)
    return (f"least-squares ARX({best[1]}, {best[2]}, 1), orders chosen on DATA_EMPS",
            sc.rmse[0] if sc.status == "ok" else None, sc.reason or "this run")


def flight_report(out_dir, seed: int = 3, ticker=None) -> Path:
    """Write the report of a simulated flight with a hidden thrust loss into ``out_dir``."""
    ticker = ticker or (lambda what: nullcontext())
    from cdam_core.sim import simulate_flight
    from cdam_core.sim.parameters import plant_dict, plant_vector, total_mass
    from cdam_core.models.greybox.registry import get_model
    from cdam_core.report.residual import write_report
    from cdam_core.residual.analyse import analyse
    ds = simulate_flight("both", duration=10.0, seed=seed, effects=["thrust_loss"],
                         declare=["arm_coupling"])
    sig = {k: ds.column(k) for k in get_model("aerial_manipulator").signals}
    m = total_mass(plant_dict(plant_vector()), with_payload=False)
    with ticker("the residual loop on the simulated flight"):
        sel = analyse("aerial_manipulator", ds.t, sig, fixed={"m": m},
                      declared=("arm_coupling",))
    return write_report(sel, out_dir, title="simulated flight, hidden thrust loss",
                        source=f"cdam_core.sim.simulate_flight('both', 10 s, seed {seed}, "
                               f"effects=['thrust_loss'], declare=['arm_coupling'])")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m cdam_core.cli.example",
                                 description="write the residual-analysis example reports")
    ap.add_argument("example", choices=["emps", "flight"])
    ap.add_argument("out_dir")
    a = ap.parse_args(argv)
    from cdam_core.cli.common import elapsed_ticker
    a.command = f"example {a.example}"

    def ticker(what):                             # the seconds elapsed, on a terminal only
        return elapsed_ticker(a, what)
    from threadpoolctl import threadpool_limits

    from cdam_core.cli.main import report_failure
    try:
        # numpy's BLAS on one thread, as `cdam residual` runs the same loop: the committed
        # reports then read the same at any BLAS thread count (its reductions' order)
        with threadpool_limits(1, user_api="blas"):
            path = emps_report(a.out_dir, ticker) if a.example == "emps" else \
                flight_report(a.out_dir, ticker=ticker)
    except (Exception, KeyboardInterrupt) as exc:   # one line and an exit code, as `cdam`
        return report_failure(f"cdam {a.command}", exc)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
