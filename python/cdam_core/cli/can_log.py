"""`cdam can-log`: record the arm's CAN bus to a standard log file (and the decoded joints)."""
from __future__ import annotations

import signal
import sys
from pathlib import Path

from cdam_core.cli.common import CliError, check_io


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "can-log", help="record a CAN bus to a candump .log/.blf (python-can) and decode C610s",
        description="Record a CAN bus with python-can's writers (format by suffix: .log candump, "
                    ".blf, .asc, .csv), flushing every 50 ms so that a killed logger leaves a "
                    "readable log. Optionally decode C610/M2006 feedback into joints.csv.")
    p.add_argument("--interface", required=True,
                   choices=["virtual", "slcan", "udp_multicast", "socketcan"])
    p.add_argument("--channel", default=None,
                   help="channel (udp_multicast: multicast group, default 239.74.163.2; "
                        "slcan: serial port or socket://HOST:PORT)")
    p.add_argument("--port", type=int, default=None, help="udp_multicast UDP port (default 43113)")
    p.add_argument("-o", "--output", required=True, help="log file (.log, .blf, .asc, .csv)")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds to record (default: until Ctrl-C or SIGTERM)")
    p.add_argument("--decoded", default=None, help="also write the decoded joints (dataset CSV)")
    p.add_argument("--rate", type=float, default=1000.0, help="rate of --decoded, Hz")
    p.add_argument("--kt", type=float, default=None, help="torque constant at the output, N m/A")
    p.add_argument("--flush-interval", type=float, default=0.05, help="seconds between flushes")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.record.can import C610Recorder, log_bus, open_bus
    from cdam_core.record.can.codec import DEFAULT_KT_OUTPUT
    from cdam_core.record.dataset import write_dataset

    from cdam_core.record.dataset import sidecar_path

    out = Path(args.output)
    dec = Path(args.decoded) if args.decoded else None
    check_io(files=[("-o", out), ("--decoded", dec),
                    ("--decoded (sidecar)", dec and sidecar_path(dec))])
    recorder = C610Recorder(kt=args.kt if args.kt is not None else DEFAULT_KT_OUTPUT)
    stop = {"flag": False}

    def on_term(signum, frame):
        stop["flag"] = True
    try:
        bus = open_bus(args.interface, args.channel, port=args.port)
    except Exception as exc:  # python-can raises its own errors for unavailable interfaces
        raise CliError(f"cannot open {args.interface} bus: {exc}") from None
    old = signal.signal(signal.SIGTERM, on_term)
    try:
        stats = log_bus(bus, out, duration=args.duration,
                        listeners=[recorder.on_message_received] if args.decoded else [],
                        flush_interval=args.flush_interval, should_stop=lambda: stop["flag"],
                        on_start=None if args.quiet else
                        lambda: print(f"cdam can-log: recording to {out}", file=sys.stderr,
                                      flush=True))
    except KeyboardInterrupt:
        stats = {"frames": -1, "seconds": float("nan")}
    finally:
        bus.shutdown()
        signal.signal(signal.SIGTERM, old)
    if not args.quiet:
        print(f"{stats['frames']} frames in {stats['seconds']:.2f} s -> {out}")
    if args.decoded:
        if not args.quiet:
            print(f"frames by kind: {dict(recorder.counts)}; malformed: {recorder.malformed}")
        write_dataset(Path(args.decoded), recorder.to_dataset(rate=args.rate))
        if not args.quiet:
            print(f"decoded joints -> {args.decoded}")
    return 0
