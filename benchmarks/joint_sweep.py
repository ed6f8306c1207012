"""Accuracy sweep (not a speed benchmark): `cdam residual`'s analysis with its defaults on random
flexible joints that no test was written against (tests/residual/random_joints.py, plain numpy),
each parameter against the generator's truth, with the estimator's relative sigma beside it.

    .venv/bin/python benchmarks/joint_sweep.py --seeds 0:40 --json out/joint_sweep.json

About 10-500 s of CPU per record (output error is the slow part); two workers by default.
Session 19 (40 seeds, 2026-11-28): see README, "The same generator beyond its tested
conditions"."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from multiprocessing import Pool

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "residual"))

PARAMS = ("Im", "I", "Ks", "Dl", "Dm", "Kd")


def run(seed: int) -> dict:
    from cdam_core.residual.analyse import analyse
    from random_joints import stable_record
    p, rec, amp, Fc = stable_record(seed)
    if rec is None:
        return {"seed": seed, "drawn": p, "status": "skipped: the drawn loop is unstable"}
    t0 = time.process_time()
    try:
        sel = analyse("flexible_joint", rec["t"], {k: rec[k] for k in ("tau_m", "theta_m", "q")},
                      free_run=False)
    except Exception as exc:   # noqa: BLE001 - a sweep reports every failure and goes on
        return {"seed": seed, "drawn": p, "status": f"error {type(exc).__name__}: {exc}"}
    th, sd = dict(sel.final.theta), dict(sel.final.std)
    err = {k: th.get(k, float("nan")) / p[k] - 1 for k in PARAMS}
    if p["G"]:
        err["G"] = th.get("G", 0.0) / p["G"] - 1
    fc = next((s.candidate.effect.parameters(sel.final.theta, sel.final.model).get("Fc")
               for s in sel.steps if s.candidate.effect.key == "coulomb_friction@tau_m"), None)
    if Fc:
        err["Fc"] = fc / Fc - 1 if fc is not None else float("nan")
    return {"seed": seed, "drawn": p, "Fc": Fc, "status": "ok", "relative_error": err,
            "relative_sigma": {k: sd[k] / abs(th[k]) for k in err if th.get(k) and k in sd},
            "findings": [s.candidate.effect.key for s in sel.steps],
            "estimator": sel.settings["estimator"]["chosen"],
            "timing": sel.settings["timing"]["chosen"],
            "cutoffs_hz": sel.settings["filter_choice"].get("chosen_hz"),
            "model": sel.final.model.name, "cpu_s": time.process_time() - t0}


def _row(r: dict) -> str:
    p = r["drawn"]
    what = (f"{r['seed']:3d} {int(p['fs']):4d} Hz {p['plane'][0]} {p['control']:5s} "
            f"{p['excitation']:9s}")
    if r["status"] != "ok":
        return f"{what} {r['status']}"
    bad = {k: f"{100 * v:+.0f} % (sigma {100 * r['relative_sigma'].get(k, float('nan')):.1f})"
           for k, v in r["relative_error"].items() if not abs(v) < 0.05}
    return (f"{what} {r['estimator'][:14]:14s} {', '.join(r['findings']) or '-':40s} "
            + ("all within 5 %" if not bad else "; ".join(f"{k} {v}" for k, v in bad.items())))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("--seeds", default="0:40", help="first:last (exclusive) seed")
    ap.add_argument("--workers", type=int, default=2, help="processes")
    ap.add_argument("--json", help="write every record's result here")
    a = ap.parse_args(argv)
    try:
        lo, hi = (int(x) for x in a.seeds.split(":"))
    except ValueError:
        ap.error(f"--seeds: expected first:last, got {a.seeds!r}")
    if not 0 <= lo < hi or a.workers < 1:
        ap.error("--seeds: need 0 <= first < last; --workers: at least 1")
    out = []
    with Pool(a.workers) as pool:
        for r in pool.imap(run, range(lo, hi)):
            out.append(r)
            print(_row(r), flush=True)
            if a.json:   # written as it goes: an interrupted sweep keeps what it has
                with open(a.json, "w") as f:
                    json.dump(out, f, indent=1, default=float)
    ok = [r for r in out if r["status"] == "ok"]
    good = sum(all(abs(v) < 0.05 for k, v in r["relative_error"].items()
                   if k in ("Im", "I", "Ks")) for r in ok)
    print(f"{len(ok)} records analysed; Im, I and Ks within 5 % on {good}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
