"""`cdam merge`: align the arm's record to the flight's clock and write one record."""
from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "merge", help="align joints.csv to flight.csv (clock offset by cross-correlation)",
        description="Estimate the offset between the two controllers' clocks by "
                    "cross-correlating one motion both records see, report it with its "
                    "uncertainty, align, resample onto one grid and write the dataset format.")
    p.add_argument("flight", help="flight record (dataset CSV, e.g. from import-ulog)")
    p.add_argument("joints", help="arm record (dataset CSV, e.g. from import-can)")
    p.add_argument("-o", "--output", required=True, help="merged dataset CSV")
    p.add_argument("--pair", default=None,
                   help="FLIGHT_COL:JOINT_COL seeing one motion (default: first shared name)")
    p.add_argument("--rate", type=float, default=None, help="output rate, Hz (default flight's)")
    p.add_argument("--max-lag", type=float, default=None, help="largest offset searched, s")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.record.dataset import read_dataset, write_dataset
    from cdam_core.record.merge import merge_records

    from cdam_core.cli.common import check_io
    from cdam_core.record.dataset import sidecar_path

    out = Path(args.output)
    check_io(inputs=[("FLIGHT", args.flight), ("JOINTS", args.joints)],
             files=[("-o", out), ("-o (sidecar)", sidecar_path(out))])
    pair = None
    if args.pair:
        parts = args.pair.split(":")
        if len(parts) != 2 or not all(parts):
            raise ValueError(f"--pair: expected FLIGHT_COL:JOINT_COL, got {args.pair!r}")
        pair = (parts[0].strip(), parts[1].strip())
    flight, joints = read_dataset(Path(args.flight)), read_dataset(Path(args.joints))
    ds, est = merge_records(flight, joints, pair=pair, rate=args.rate, max_lag=args.max_lag)
    write_dataset(Path(args.output), ds)
    p = ds.meta["clock_offset"]["pair"]
    print(f"clock offset (joints + offset = flight): {est.offset:.6f} s "
          f"+- {est.uncertainty:.6f} s (1 sigma), pair {p[0]}:{p[1]}, "
          f"peak correlation {est.correlation:+.3f}")
    print(f"{len(ds)} samples at {ds.rate:g} Hz, {len(ds.columns)} columns -> {args.output}")
    return 0
