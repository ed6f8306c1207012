"""`cdam import-ulog`: a PX4 flight log (ULog) into the dataset format."""
from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "import-ulog", help="convert a PX4 ULog (attitude, position, setpoints, motors) to CSV",
        description="Read a PX4 ULog with pyulog: attitude (quaternion -> Z-Y-X Euler), local "
                    "position, thrust/torque setpoints (normalised), motor outputs; convert "
                    "NED/FRD to NWU/FLU (Z up); resample to one rate (angles unwrapped + linear, "
                    "positions linear, setpoints and motors zero-order hold); report gaps and "
                    "whether the log comes from SITL or hardware.")
    p.add_argument("ulog", help="PX4 .ulg file")
    p.add_argument("-o", "--output", required=True, help="dataset CSV to write")
    p.add_argument("--rate", type=float, default=1000.0, help="output rate in Hz (default 1000)")
    p.add_argument("--gap-factor", type=float, default=5.0,
                   help="report intervals longer than this many median intervals (default 5)")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.record.dataset import write_dataset
    from cdam_core.record.ulog import load_ulog

    from cdam_core.cli.common import check_io, warn
    from cdam_core.record.dataset import sidecar_path

    out = Path(args.output)
    check_io(inputs=[("ULOG", args.ulog)], files=[("-o", out), ("-o (sidecar)", sidecar_path(out))])
    ds = load_ulog(Path(args.ulog), rate=args.rate, gap_factor=args.gap_factor)
    m = ds.meta
    write_dataset(Path(args.output), ds)
    print(f"{Path(args.ulog).name}: {m['platform']} log (sys_name {m['sys_name']!r}, "
          f"ver_hw {m['ver_hw']!r})")
    print(f"topics: {m['topics']}")
    if m["missing"]:
        warn("import-ulog", f"missing (record is partial): {'; '.join(m['missing'])}")
    for col, gaps in m["gaps"].items():
        worst = max(g["duration"] for g in gaps)
        warn("import-ulog", f"gap: {col}: {len(gaps)} interval(s) > {args.gap_factor:g} x "
                            f"median, longest {worst:.3f} s")
    for d in m["dropouts"]:
        warn("import-ulog", f"logger dropout at {d['start']:.3f} s for {d['duration']:.3f} s")
    print(f"{len(ds)} samples at {args.rate:g} Hz ({ds.t[0]:.3f}..{ds.t[-1]:.3f} s), "
          f"columns {', '.join(ds.columns)} -> {args.output}")
    return 0
