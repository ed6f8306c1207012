"""`cdam import-can`: decode a CAN log (C610/M2006 feedback) into the dataset format."""
from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "import-can", help="decode a CAN log (.log/.asc/.blf/.csv) of C610s into joints.csv",
        description="Read a python-can log, decode C610/M2006 feedback (DBC shipped with "
                    "cdam_core) into theta/omega/i/tau per joint, resample and write the "
                    "dataset format. Malformed frames are counted and reported.")
    p.add_argument("log", help="log file: .log (candump), .asc, .blf or .csv")
    p.add_argument("-o", "--output", required=True, help="dataset CSV to write")
    p.add_argument("--rate", type=float, default=1000.0, help="output rate, Hz (default 1000)")
    p.add_argument("--joints", default="1:m1,2:m2",
                   help="motor id to joint name, e.g. 1:m1,2:m2 (default)")
    p.add_argument("--kt", type=float, default=None, help="torque constant at the output, N m/A")
    p.set_defaults(func=run)


def parse_joints(text: str) -> dict[int, str]:
    """'1:m1,2:m2' -> {1: 'm1', 2: 'm2'}."""
    out = {}
    for part in text.split(","):
        try:
            mid, name = part.split(":")
            out[int(mid)] = name.strip()
        except ValueError:
            raise ValueError(f"--joints: expected ID:NAME[,ID:NAME...], got {text!r}") from None
    return out


def run(args) -> int:
    from cdam_core.record.can import C610Recorder, iter_log
    from cdam_core.record.can.codec import DEFAULT_KT_OUTPUT
    from cdam_core.record.dataset import write_dataset

    rec = C610Recorder(joints=parse_joints(args.joints),
                       kt=args.kt if args.kt is not None else DEFAULT_KT_OUTPUT)
    report: dict = {}
    for msg in iter_log(Path(args.log), report):
        rec.on_message_received(msg)
    ds = rec.to_dataset(rate=args.rate)
    ds.meta["log"] = str(args.log)
    ds.meta["log_truncated"] = report.get("truncated", False)
    write_dataset(Path(args.output), ds)
    print(f"{sum(rec.counts.values())} frames: {dict(rec.counts)}")
    print(f"malformed: {rec.malformed}")
    if report.get("truncated"):
        print(f"log ends in a partial record (reading stopped there): {report['truncated']}")
    gaps = {k: len(v) for k, v in ds.meta["gaps"].items()}
    print(f"{len(ds)} samples at {args.rate:g} Hz, {ds.t[-1]:.3f} s; gaps > 10 ms: {gaps} "
          f"-> {args.output}")
    return 0
