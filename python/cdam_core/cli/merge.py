"""`cdam merge`: align the arm's record to the flight's clock and write one record."""
from __future__ import annotations

from pathlib import Path

from cdam_core.cli.common import CliError, add_outputs, check_io, note, warn, write_json


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "merge", help="align joints.csv to flight.csv (clock offset by cross-correlation)",
        description="Estimate the offset between the two controllers' clocks by "
                    "cross-correlating one motion both records see, report it with its "
                    "uncertainty, align, resample onto one grid and write the dataset format. "
                    "An alignment whose peak correlation is not significant (unrelated smooth "
                    "signals peak as high with probability above --alpha, given the effective "
                    "number of independent samples and the lags searched) is refused: exit 2, "
                    "nothing written, unless --force.")
    p.add_argument("flight", help="flight record (dataset CSV, e.g. from import-ulog)")
    p.add_argument("joints", help="arm record (dataset CSV, e.g. from import-can)")
    p.add_argument("-o", "--output", required=True, help="merged dataset CSV")
    p.add_argument("--pair", default=None,
                   help="FLIGHT_COL:JOINT_COL seeing one motion (default: first shared name)")
    p.add_argument("--rate", type=float, default=None, help="output rate, Hz (default flight's)")
    p.add_argument("--max-lag", type=float, default=None,
                   help="largest offset searched, s (default: any lag leaving at least a "
                        "quarter of the shorter record overlapping)")
    p.add_argument("--alpha", type=float, default=0.01,
                   help="significance level the peak correlation must reach")
    p.add_argument("--force", action="store_true",
                   help="merge even when the correlation is not significant (marked "
                        "'significant': false in the sidecar)")
    add_outputs(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.record.dataset import read_dataset, sidecar_path, write_dataset
    from cdam_core.record.merge import merge_records

    out = Path(args.output)
    check_io(inputs=[("FLIGHT", args.flight), ("JOINTS", args.joints)],
             files=[("-o", out), ("-o (sidecar)", sidecar_path(out)), ("--json", args.json)],
             folders=[("--report", args.report)])
    if not 0 < args.alpha < 1:
        raise CliError(f"--alpha: expected a significance level in (0, 1), got {args.alpha}")
    pair = None
    if args.pair:
        parts = args.pair.split(":")
        if len(parts) != 2 or not all(parts):
            raise ValueError(f"--pair: expected FLIGHT_COL:JOINT_COL, got {args.pair!r}")
        pair = (parts[0].strip(), parts[1].strip())
    flight, joints = read_dataset(Path(args.flight)), read_dataset(Path(args.joints))
    ds, est = merge_records(flight, joints, pair=pair, rate=args.rate, max_lag=args.max_lag,
                            alpha=args.alpha, force=args.force)
    write_dataset(out, ds)
    off = ds.meta["clock_offset"]
    p = off["pair"]
    lines = [f"clock offset (joints + offset = flight): {est.offset:.6f} s "
             f"+- {est.uncertainty:.6f} s (1 sigma), pair {p[0]}:{p[1]}",
             f"peak correlation {est.correlation:+.3f}, p = {est.p_value:.2g} "
             f"({est.n_eff:.0f} effective samples, {est.lags_searched} lags searched)",
             f"{len(ds)} samples at {ds.rate:g} Hz, {len(ds.columns)} columns -> {out}"]
    print("\n".join(lines))
    if not off["significant"]:
        warn("merge", f"merged with --force: the alignment is not significant "
                      f"(p = {est.p_value:.2g} > {args.alpha:g}); the offset may be meaningless")
    results = {"flight": str(args.flight), "joints": str(args.joints), "output": str(out),
               "clock_offset": off, "samples": len(ds), "rate": ds.rate, "columns": ds.columns}
    if args.json:
        write_json(args.json, results)
    if args.report:
        from cdam_core.report.summary import write_summary_report
        md = write_summary_report(
            args.report, f"Clock alignment of {Path(args.joints).name} to "
                         f"{Path(args.flight).name}", lines, results,
            notes="The offset maximises the cross-correlation of the pair; its uncertainty is "
                  "the spread of the offsets found on eight pieces of the overlap. p is the "
                  "chance that unrelated smooth signals peak as high (see "
                  "cdam_core.record.merge); a p above the significance level means the pair "
                  "does not show one motion.")
        note(args, f"report: {md}")
    return 0
