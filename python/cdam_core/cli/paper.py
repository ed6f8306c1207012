"""`cdam paper`: the paper's study (Tables 2 and 3, Figs. 8-15) on simulated flights."""
from __future__ import annotations

from cdam_core.cli.common import (CliError, check_io, note, parse_narx, show_progress,
                                  write_json)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "paper", help="reproduce the paper's Tables 2 and 3 and Figs. 8-15 on simulated flights",
        description="Simulate experiments (i) and (ii) and their validation records, identify with "
                    "IBOA-BP, BOA-BP and CABC-BP (static map, NARX network, hybrid ARX + "
                    "network), and write index.md/html, "
                    "results.json, predictions.npz, figures and the records into --out.")
    p.add_argument("--seeds", type=int, default=4,
                   help="identification seeds per algorithm (default 4: the fewest for which a "
                        "rank-sum test can reach p < 0.05)")
    p.add_argument("--out", "--report", dest="out", metavar="DIR", default="paper_out",
                   help="output folder: the report, results.json, figures, records "
                        "(default paper_out)")
    p.add_argument("--json", metavar="FILE", default=None,
                   help="also write results.json's content to FILE")
    p.add_argument("--rate", type=float, default=200.0,
                   help="training/evaluation rate in Hz after smoothing at 1 kHz (default 200; "
                        "1000 = no decimation)")
    p.add_argument("--smoothing", type=int, default=5,
                   help="five-point smoothing passes (default 5)")
    p.add_argument("--narx", default="2,2,1",
                   help="NARX orders na,nb,nk of the second section, or 'none' (default 2,2,1)")
    p.add_argument("--no-hybrid", action="store_true",
                   help="skip the third section (hybrid linear ARX + network on its residual)")
    p.add_argument("--horizon", type=float, action="append", default=None, metavar="SECONDS",
                   help="k-step-ahead prediction horizon of the dynamic sections (repeatable; "
                        "default 0.1)")
    p.add_argument("--flight-seed", type=int, default=0, help="seed of the simulated flights")
    p.add_argument("--duration", type=float, default=20.0,
                   help="seconds per experiment record (validation records: half; default 20)")
    p.add_argument("--hidden", type=int, default=20, help="hidden nodes (default 20)")
    p.add_argument("--iterations", type=int, default=50, help="Tmax (default 50)")
    p.add_argument("--population", type=int, default=20, help="g and CABC Np (default 20)")
    p.add_argument("--epochs", type=int, default=50, help="LM epochs at most (default 50)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[:param=value,...]",
                   help="extra simulator effect (repeatable; see cdam simulate --list-effects)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress and no notes on stderr (warnings stay)")
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.paper import PaperConfig, run_paper
    from cdam_core.report.paper.tables import mode_label

    if args.seeds < 1:
        raise CliError(f"--seeds: must be >= 1, got {args.seeds}")
    for name in ("hidden", "population", "epochs"):
        if getattr(args, name) < 1:
            raise CliError(f"--{name}: must be >= 1, got {getattr(args, name)}")
    if args.iterations < 0 or args.smoothing < 0:
        raise CliError("--iterations/--smoothing: must be >= 0")
    if not args.duration > 0:
        raise CliError(f"--duration: must be positive, got {args.duration}")
    check_io(files=[("--json", args.json)], folders=[("--out", args.out)])
    try:
        cfg = PaperConfig(seeds=args.seeds, flight_seed=args.flight_seed, duration=args.duration,
                          rate=args.rate, smoothing=args.smoothing, hidden=args.hidden,
                          population=args.population, iterations=args.iterations,
                          lm_epochs=args.epochs, narx=parse_narx(args.narx, allow_none=True), effects=list(args.effect),
                          hybrid=not args.no_hybrid,
                          horizons=tuple(args.horizon) if args.horizon else (0.1,))
    except ValueError as exc:
        raise CliError(str(exc)) from None
    result = run_paper(cfg, args.out, progress=show_progress(args))
    if args.json:
        write_json(args.json, result)
    algo = cfg.algos[0]
    for rec, label in (("test", "Table 2"), ("validation", "Table 3")):
        print(f"{label}, {algo} mean r (yes: every algorithm reaches its published r)")
        for o, flags in result["reach"].items():
            cells = []
            for sec, t in result["tables"].items():
                for mode, rows in t["r"][rec].items():
                    m = rows[o][algo]["mean"]
                    cells.append(f"{sec} {mode_label(mode)} "
                                 f"{'n/a' if m is None else format(m, '.4f')} "
                                 f"{'yes' if flags[f'{sec}/{rec}/{mode}'] else 'no'}")
            paper = result["published"]["table2" if rec == "test" else "table3"][o][algo]
            print(f"  {o:6s} paper {paper:.4f} | " + " | ".join(cells))
    note(args, f"index: {args.out}/index.md ({result['seconds']['total']:.1f} s)")
    return 0
