"""Every speed figure of cdam_core, from one entry point.

    python benchmarks/run.py [--only NAME[,NAME...]] [--json FILE] [--list]

Each benchmarks/bench_*.py module defines ``BENCHMARKS = {name: fn}``; fn() returns a dict with
at least "ratio" (the core's speed over the fairest reference we could write, run in the same
process, >1 is faster; None when there is no fair one) and "seconds" (the core's time), and
where it has them "reference" (what the reference is) and "reference_seconds", "old_ratio" and
"old_reference" (the earlier, less careful reference), "bound_seconds" and "over_bound" (the
core's time over a lower bound, e.g. the FLOPs at numpy's single-core DGEMM rate measured in the
same run), plus its own figures. Every entry also records the CPU model, the SIMD level and the
load averages before and after it (the machine may be shared: the figures are best-of-N, thread
CPU time on one thread). Prints a table and the details; --json writes {NAME: {...}}.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))   # the bench modules import timing.py and numpy_baselines.py

from timing import machine  # noqa: E402


def discover() -> dict:
    found = {}
    for path in sorted(HERE.glob("bench_*.py")):
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        for name, fn in getattr(mod, "BENCHMARKS", {}).items():
            found[name] = fn
    return found


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", help="comma-separated benchmark names")
    ap.add_argument("--json", help="write the results to this JSON file")
    ap.add_argument("--list", action="store_true", help="list the benchmark names and exit")
    args = ap.parse_args(argv)
    benches = discover()
    if args.list:
        print("\n".join(benches))
        return 0
    names = list(benches)
    if args.only:
        names = [n.strip() for n in args.only.split(",") if n.strip()]
        unknown = [n for n in names if n not in benches]
        if unknown:
            print(f"run.py: error: unknown benchmark(s) {unknown}; known: {sorted(benches)}", file=sys.stderr)
            return 2
    results = {}
    for name in names:
        print(f"running {name} ...", file=sys.stderr, flush=True)
        before = machine()
        t = time.perf_counter()
        res = benches[name]()
        res.setdefault("wall_seconds", time.perf_counter() - t)
        res["machine"] = {**before, "load_average_after": machine()["load_average"]}
        results[name] = res
    _print_table(results)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


_COLUMNS = ("ratio", "seconds", "reference", "reference_seconds", "over_bound", "old_ratio",
            "old_reference", "machine", "wall_seconds")


def _print_table(results: dict) -> None:
    m = next(iter(results.values()), {}).get("machine", machine())
    print(f"\nCPU {m['cpu']} ({m['simd']}, {m['cores']} cores)")
    print(f"{'benchmark':<18} {'ratio':>7} {'core s':>10} {'ref s':>10} {'/bound':>7} "
          f"{'old':>7} {'load':>11}  fairest reference")
    for name, r in results.items():
        if not r or "machine" not in r or len(r) <= 2:
            print(f"{name:<18} (not run: tools missing)")
            continue
        load = f"{r['machine']['load_average'][0]:.2f}-{r['machine']['load_average_after'][0]:.2f}"
        print(f"{name:<18} {_fmt(r.get('ratio')):>7} {_fmt(r.get('seconds')):>10} "
              f"{_fmt(r.get('reference_seconds', '-')):>10} {_fmt(r.get('over_bound', '-')):>7} "
              f"{_fmt(r.get('old_ratio', '-')):>7} {load:>11}  {r.get('reference', '-')}")
    print()
    for name, r in results.items():
        extra = ", ".join(f"{k}={_fmt(v)}" for k, v in r.items() if k not in _COLUMNS)
        if extra:
            print(f"{name}: {extra}")


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


if __name__ == "__main__":
    sys.exit(main())
