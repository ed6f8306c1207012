"""`cdam import-can`: decode a CAN log (C610/M2006 feedback) into the dataset format."""
from __future__ import annotations

import argparse
from pathlib import Path

from cdam_core.cli.common import EXIT_CODES, CliError, check_io, warn

EPILOG = """what is lost is counted, never hidden:
  skipped lines   text-log lines that cannot be parsed (bad hex, stray text, bad base64),
                  listed with their line numbers; reading goes on after each
  skipped objects BLF objects or containers that fail their checks (header, size, zlib
                  checksum), listed with their byte offsets and sizes; reading goes on at
                  the next object
  excluded frames feedback frames with a NaN/Inf timestamp, out of time order (one frame
                  stamped in the future is excluded, not the frames after it), or alone
                  between two gaps
  gap samples     grid samples not written because a joint's feedback has a gap longer than
                  --gap ms: t jumps over the gap, nothing is interpolated across it
A last line cut by a killed logger is reported as a partial record (no loss of a whole frame).

""" + EXIT_CODES.replace("(import-can: data lost, see the summary)",
                         "(lines skipped, frames excluded or gap samples)")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "import-can", help="decode a CAN log (.log/.asc/.blf/.csv) of C610s into joints.csv",
        description="Read a python-can log, decode C610/M2006 feedback (DBC shipped with "
                    "cdam_core) into theta/omega/i/tau per joint, resample and write the "
                    "dataset format. Malformed frames are counted and reported.",
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EPILOG)
    p.add_argument("log", help="log file: .log (candump), .asc, .blf or .csv")
    p.add_argument("-o", "--output", required=True, help="dataset CSV to write")
    p.add_argument("--rate", type=float, default=1000.0, help="output rate, Hz (default 1000)")
    p.add_argument("--gap", type=float, default=10.0,
                   help="feedback gap left out of the record, ms (default 10)")
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
    from cdam_core.record.dataset import sidecar_path, write_dataset

    out = Path(args.output)
    check_io(inputs=[("log", args.log)],
             files=[("-o", out), ("-o (sidecar)", sidecar_path(out))])
    if not args.gap > 0:
        raise CliError(f"--gap: expected a positive number of ms, got {args.gap}")
    rec = C610Recorder(joints=parse_joints(args.joints),
                       kt=args.kt if args.kt is not None else DEFAULT_KT_OUTPUT)
    report: dict = {}
    for msg in iter_log(Path(args.log), report):
        rec.on_message_received(msg)
    ds = rec.to_dataset(rate=args.rate, gap_threshold=args.gap / 1000.0)
    m = ds.meta
    m["log"] = str(args.log)
    m["log_truncated"] = report["truncated"]
    if Path(args.log).suffix.lower() == ".blf":
        m["skipped_objects"] = {"count": report["skipped_objects"],
                                "bytes": report["skipped_bytes"], "objects": report["skipped"]}
    else:
        m["skipped_lines"] = {"count": report["skipped_lines"], "lines": report["skipped"]}
    write_dataset(out, ds)
    print(f"{sum(rec.counts.values())} frames: {dict(rec.counts)}")
    print(f"malformed: {rec.malformed}")
    if report["truncated"]:
        warn("import-can", f"log ends in a partial record (cut line not read): "
                           f"{report['truncated']}")
    skipped, bad_objects = report["skipped_lines"], report["skipped_objects"]
    for count, what, key, size in ((skipped, "lines", "line", ""),
                                   (bad_objects, "objects", "offset",
                                    f", {report['skipped_bytes']} bytes")):
        if count:
            where = ", ".join(str(s[key]) for s in report["skipped"])
            more = "" if count <= len(report["skipped"]) else ", ..."
            unit = "line" if key == "line" else "byte"
            warn("import-can", f"skipped {what}: {count}{size} ({unit} {where}{more}); "
                               f"first: {report['skipped'][0]['reason']}")
    nonfinite = rec.malformed["non_finite_time"]
    if nonfinite:
        warn("import-can", f"excluded frames: {nonfinite} with a NaN/Inf timestamp")
    n_excl = 0
    for joint, ex in m["excluded"].items():
        for kind, v in ex.items():
            if v["count"]:
                n_excl += v["count"]
                times = ", ".join(f"{x:.6f}" for x in v["times"][:5])
                warn("import-can", f"excluded frames: {joint}: {v['count']} "
                                   f"{kind.replace('_', ' ')} (timestamps {times}"
                                   f"{', ...' if v['count'] > 5 else ''})")
    gaps = {k: len(v) for k, v in m["gaps"].items()}
    print(f"{len(ds)} samples at {args.rate:g} Hz in {len(m['gapless_rows'])} segment(s), "
          f"{ds.t[-1]:.3f} s; gaps > {args.gap:g} ms: {gaps}, gap samples left out: "
          f"{m['gap_samples']} -> {args.output}")
    lost = skipped + bad_objects + nonfinite + n_excl + m["gap_samples"]
    if lost:
        objects = f"{bad_objects} skipped object(s), " if bad_objects else ""
        warn("import-can", f"incomplete: {skipped} skipped line(s), {objects}"
                           f"{nonfinite + n_excl} excluded frame(s), {m['gap_samples']} gap "
                           f"sample(s)")
    return 1 if lost else 0
