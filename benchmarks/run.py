"""Every speed figure of cdam_core, from one entry point.

    python benchmarks/run.py [--only NAME[,NAME...]] [--json FILE] [--list]

Each benchmarks/bench_*.py module defines ``BENCHMARKS = {name: fn}``; fn() returns a dict with
at least "ratio" (the core's speed over a reference run in the same process, >1 is faster) and
"seconds" (the core's time), plus its own figures. Prints a table; --json writes
{NAME: {...}}. Machines here are noisy: read the ratios, not the absolute times.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


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
        t = time.perf_counter()
        res = benches[name]()
        res.setdefault("wall_seconds", time.perf_counter() - t)
        results[name] = res
    print(f"\n{'benchmark':<16} {'ratio':>8} {'seconds':>10}  details")
    for name, r in results.items():
        extra = ", ".join(f"{k}={_fmt(v)}" for k, v in r.items() if k not in ("ratio", "seconds", "wall_seconds"))
        print(f"{name:<16} {_fmt(r.get('ratio')):>8} {_fmt(r.get('seconds')):>10}  {extra}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


if __name__ == "__main__":
    sys.exit(main())
