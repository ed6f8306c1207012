"""Entry point of the `cdam` command (``python -m cdam_core`` does the same)."""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys

from cdam_core import __version__

# Command modules in the order `cdam --help` lists them. A module that is not present yet
# (a command still being built) is skipped; one that is present but fails to import is an error.
COMMANDS = [
    "paper",
    "simulate",
    "identify",
    "residual",
    "evaluate",
    "monitor",
    "batch",
    "export_firmware",
    "firmware",
    "can_log",
    "import_can",
    "import_ulog",
    "merge",
    "demo",
]


def build_parser() -> argparse.ArgumentParser:
    parser = CdamParser(
        prog="cdam",
        description="Identify, check and fly the dynamics of a cable-driven aerial manipulator.",
        epilog=EXIT_CODES)
    parser.add_argument("--version", action="version", version=f"cdam {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        modname = f"cdam_core.cli.{name}"
        if importlib.util.find_spec(modname) is None:
            continue
        importlib.import_module(modname).register(sub)
    return parser


from cdam_core.cli.common import EXIT_CODES, CdamParser, CliError  # noqa: E402  (re-exported)


def _message(exc: BaseException) -> tuple[str, int]:
    """(one-line message, exit code) of an error that ends a command."""
    if isinstance(exc, CliError):
        return str(exc), exc.code
    if isinstance(exc, OSError):
        code = 2 if isinstance(exc, FileNotFoundError) else 3   # a missing input: bad input
        if exc.strerror:
            name = f"{exc.filename}: " if exc.filename is not None else ""
            return f"{name}{exc.strerror}", code
        return str(exc) or type(exc).__name__, code
    if isinstance(exc, MemoryError):
        return "out of memory (input too large for this machine)", 3
    if isinstance(exc, KeyError):
        return str(exc.args[0] if exc.args else exc), 2
    if isinstance(exc, ZeroDivisionError):
        return f"division by zero: {exc} (an argument or the data is zero where it must not be)", 2
    return str(exc) or type(exc).__name__, 2


class _PipeSafeStdout:
    """stdout that goes quiet once its reader has gone (``cdam ... | head``): the command
    still completes and writes its files; nothing is reported as an error."""

    def __init__(self, stream):
        self._s, self.broken = stream, False

    def write(self, text):
        if not self.broken:
            try:
                return self._s.write(text)
            except BrokenPipeError:
                self.broken = True
        return len(text)

    def flush(self):
        if not self.broken:
            try:
                self._s.flush()
            except BrokenPipeError:
                self.broken = True

    def __getattr__(self, name):
        return getattr(self._s, name)


def main(argv: list[str] | None = None) -> int:
    """Run one command; every failure is one stderr line and an exit code (see EXIT_CODES)."""
    out = sys.stdout if isinstance(sys.stdout, _PipeSafeStdout) else _PipeSafeStdout(sys.stdout)
    sys.stdout = out
    try:
        return _main(argv)
    finally:
        out.flush()
        if out.broken:      # keep the interpreter's final flush from complaining
            try:
                os.dup2(os.open(os.devnull, os.O_WRONLY), out._s.fileno())
            except (OSError, ValueError, AttributeError):
                pass
        sys.stdout = out._s


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"cdam {args.command}: error: interrupted", file=sys.stderr)
        return 130
    except (CliError, OSError, MemoryError, ValueError, ArithmeticError, KeyError, TypeError,
            UnicodeError, RecursionError) as exc:
        msg, code = _message(exc)
        msg = " ".join(str(msg).split())          # one line
        print(f"cdam {args.command}: error: {msg}", file=sys.stderr)
        return code
    except Exception as exc:  # noqa: BLE001 - a bug; still one line, no traceback
        msg = " ".join(f"{type(exc).__name__}: {exc}".split())
        print(f"cdam {args.command}: error: internal error ({msg}); please report it",
              file=sys.stderr)
        return 4


if __name__ == "__main__":
    sys.exit(main())
