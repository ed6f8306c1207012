"""Entry point of the `cdam` command (``python -m cdam_core`` does the same).

Ctrl-C at any time, the imports at start-up included, ends the command with one line
(``cdam: error: interrupted``, or ``cdam COMMAND: ...`` once the command is known) and exit
code 130: while this module is imported a SIGINT handler exits at once (put back afterwards, so
importing the module changes nothing for a program that uses it); from then on ``main`` catches
KeyboardInterrupt around everything it does (building the parser imports every command).
"""
from __future__ import annotations

import os
import signal
import sys


def _interrupted_at_start(signum, frame):
    # exit here, not by an exception: raised inside an extension's import (numpy's C core
    # importing ``datetime``) the exception becomes that module's ImportError and a traceback
    # (seen in CI). Nothing has been written yet while the modules import.
    sys.stderr.write("cdam: error: interrupted\n")
    sys.stderr.flush()
    os._exit(130)


try:        # only the main thread may set handlers; elsewhere nothing to do
    _PREVIOUS = signal.signal(signal.SIGINT, _interrupted_at_start) \
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler else None
except ValueError:
    _PREVIOUS = None

import argparse  # noqa: E402  (after the handler: a Ctrl-C while importing is one line)
import importlib  # noqa: E402
import importlib.util  # noqa: E402

from cdam_core import __version__  # noqa: E402

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

if _PREVIOUS is not None:
    signal.signal(signal.SIGINT, _PREVIOUS)


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
    args = None

    def name() -> str:             # the command once it is known
        return f"cdam {args.command}" if getattr(args, "command", None) else "cdam"
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        return int(args.func(args) or 0)
    except Exception as exc:  # noqa: BLE001 - every failure is one line (report_failure)
        return report_failure(name(), exc)
    except KeyboardInterrupt as exc:
        return report_failure(name(), exc)


def report_failure(name: str, exc: BaseException) -> int:
    """Print the one-line ``NAME: error: ...`` of an exception that ended a command and return
    its exit code (EXIT_CODES): 130 interrupted, 2 bad input, 3 I/O, 4 a bug."""
    if isinstance(exc, KeyboardInterrupt):
        print(f"{name}: error: interrupted", file=sys.stderr)
        return 130
    if isinstance(exc, (CliError, OSError, MemoryError, ValueError, ArithmeticError, KeyError,
                        TypeError, UnicodeError, RecursionError)):
        msg, code = _message(exc)
        msg = " ".join(str(msg).split())          # one line
        print(f"{name}: error: {msg}", file=sys.stderr)
        return code
    msg = " ".join(f"{type(exc).__name__}: {exc}".split())
    print(f"{name}: error: internal error ({msg}); please report it", file=sys.stderr)
    return 4


if __name__ == "__main__":
    sys.exit(main())
