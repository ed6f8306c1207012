"""`cdam simulate`: simulated flights of experiments (i) and (ii) in the dataset format."""
from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="simulate a flight of experiment (i) or (ii) and write it as CSV + JSON",
        description="Simulate the rigid-flexible aerial manipulator in closed loop at 1 kHz and "
                    "write the logged record (dataset format: FILE.csv + FILE.json sidecar).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  cdam simulate --experiment i --seed 1 -o flight_i.csv\n"
               "  cdam simulate --experiment ii --effect coulomb_friction:Fc1=0.05 -o f.csv\n"
               "  cdam simulate --list-effects")
    p.add_argument("--experiment", choices=("i", "ii", "both"), default="i",
                   help="i: arm held, attitude/altitude excited; ii: hover, joints excited; "
                        "both: everything excited at once (default i)")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds (default 20; the validation record 10)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:param=value,...]",
                   help="switch an effect on (repeatable); see --list-effects")
    p.add_argument("--declare", action="append", default=[], metavar="NAME",
                   help="declare an effect in the sidecar's model (repeatable)")
    p.add_argument("--validation", action="store_true",
                   help="also write the separate 10 s validation record to FILE_validation.csv")
    p.add_argument("--noise-scale", type=float, default=1.0, help="sensor noise multiplier")
    p.add_argument("--list-effects", action="store_true", help="document every effect and exit")
    p.add_argument("-o", "--output", help="output CSV file")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.sim import describe_effects, simulate_flight, write_flight
    from cdam_core.cli.common import CliError

    if args.list_effects:
        print(describe_effects())
        return 0
    if not args.output:
        raise CliError("-o/--output: an output .csv file is required")
    out = Path(args.output)
    if out.suffix.lower() != ".csv":
        raise CliError(f"-o/--output: expected a .csv file name, got {out.name!r}")
    from cdam_core.cli.common import check_io
    from cdam_core.record.dataset import sidecar_path

    vout = out.with_name(out.stem + "_validation.csv") if args.validation else None
    check_io(files=[("-o", out), ("-o (sidecar)", sidecar_path(out)), ("--validation", vout),
                    ("--validation (sidecar)", vout and sidecar_path(vout))])
    kw = dict(experiment=args.experiment, seed=args.seed, effects=args.effect,
              declare=args.declare, noise_scale=args.noise_scale)
    ds = simulate_flight(duration=args.duration, **kw)
    write_flight(out, ds)
    print(f"wrote {out} ({len(ds)} samples, {len(ds.columns)} columns; "
          f"effects: {', '.join(ds.meta['effects'])})")
    if args.validation:
        vpath = vout
        vs = simulate_flight(validation=True, duration=None, **kw)
        write_flight(vpath, vs)
        print(f"wrote {vpath} ({len(vs)} samples, seed {vs.meta['record_seed']})")
    return 0
