"""Entry point of the `cdam` command (``python -m cdam_core`` does the same)."""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

# Command modules in the order `cdam --help` lists them. A module that is not present yet
# (a command still being built) is skipped; one that is present but fails to import is an error.
COMMANDS = [
    "paper",
    "simulate",
    "identify",
    "residual",
    "evaluate",
    "export_firmware",
    "firmware",
    "can_log",
    "import_can",
    "import_ulog",
    "merge",
    "demo",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cdam",
        description="Identify, check and fly the dynamics of a cable-driven aerial manipulator.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        modname = f"cdam_core.cli.{name}"
        if importlib.util.find_spec(modname) is None:
            continue
        importlib.import_module(modname).register(sub)
    return parser


from cdam_core.cli.common import CliError  # noqa: E402  (re-exported for the commands)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (CliError, ValueError, FileNotFoundError, KeyError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"cdam {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cdam {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
