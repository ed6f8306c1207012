"""What every command shares: the error types and exit codes, the help layout (defaults
shown), the output-path check, order parsing, JSON out, warnings and progress on stderr."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from cdam_core.base.folders import FolderError, writable_folder
from cdam_core.base.jsonio import write_json_atomic
from cdam_core.base.orders import parse_orders

__all__ = ["CliError", "CliIOError", "EXIT_CODES", "CdamParser", "HelpFormatter",
           "add_outputs", "check_io", "parse_narx", "write_json", "warn", "note",
           "show_progress", "elapsed_ticker", "add_validation_option", "validation_rule"]

EXIT_CODES = """exit codes:
  0    done
  1    done, but the result is incomplete (import-can: data lost, see the summary)
  2    usage error or bad input; nothing written
  3    I/O error (a file cannot be read, or an output cannot be written); nothing written
  4    internal error (a bug: please report it)
  130  interrupted (Ctrl-C)
Every failure is one line on stderr: 'cdam COMMAND: error: ...'."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default in --help, once: appended as '(default: X)' unless the help
    already states its default, the option is a flag, or it has none (None: see its help).
    A description or epilog with line breaks is kept as written (examples), others wrapped."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("default" in text.lower() or action.nargs == 0 or action.default is None
                or action.default is argparse.SUPPRESS or action.default == []):
            return text
        return super()._get_help_string(action)

    def _fill_text(self, text, width, indent):
        if "\n" in text:
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


class CdamParser(argparse.ArgumentParser):
    """The parser of `cdam` and of every command under it (argparse makes sub-parsers of the
    parent's class): one help layout for all, set here once."""

    def __init__(self, *args, **kwargs):
        kwargs["formatter_class"] = HelpFormatter
        super().__init__(*args, **kwargs)

    def _add_action(self, action):
        # an option given no help still shows its default
        if (action.help is None and action.option_strings and action.nargs != 0
                and action.default not in (None, argparse.SUPPRESS)):
            action.help = "default: %(default)s"
        return super()._add_action(action)


def add_outputs(p, json: bool = True, quiet: bool = True, report: bool = True) -> None:
    """The outputs every computing command offers, with one wording: --json FILE, --quiet,
    --report DIR."""
    if json:
        p.add_argument("--json", metavar="FILE", default=None,
                       help="also write the results as JSON to FILE")
    if quiet:
        p.add_argument("--quiet", action="store_true",
                       help="no progress and no notes on stderr (warnings stay)")
    if report:
        p.add_argument("--report", metavar="DIR", default=None,
                       help="write a report (index.md, figures) into DIR")


def warn(command: str, msg: str) -> None:
    """A warning: on stderr, never mixed with the results on stdout."""
    print(f"cdam {command}: warning: {msg}", file=sys.stderr)


def note(args, msg: str) -> None:
    """A note (where a file went, what runs now): on stderr, silenced by --quiet."""
    if not getattr(args, "quiet", False):
        print(f"cdam {args.command}: {msg}", file=sys.stderr, flush=True)


def show_progress(args) -> bool:
    """Progress bars only for a person watching: not with --quiet, not when stderr is a
    file or pipe (a log, CI)."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


class elapsed_ticker:
    """``with elapsed_ticker(args, "fitting"):`` a one-line progress display on stderr for a
    long computation that has no steps to count: the task and the seconds elapsed, redrawn
    every second and erased at the end. Only where :func:`show_progress` (a terminal, not
    --quiet); elsewhere it does nothing."""

    def __init__(self, args, what: str, every: float = 1.0):
        self.on = show_progress(args)
        self.text = f"cdam {getattr(args, 'command', 'cdam')}: {what}"
        self.every = every

    def _run(self):
        import time
        t0 = time.monotonic()
        while not self._stop.wait(self.every):
            sys.stderr.write(f"\r{self.text} ... {time.monotonic() - t0:.0f} s elapsed")
            sys.stderr.flush()

    def __enter__(self):
        if self.on:
            import threading
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        if self.on:
            self._stop.set()
            self._thread.join()
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()
        return False


class CliError(Exception):
    """A user error: printed as 'cdam COMMAND: error: ...' with exit code ``code`` (2)."""

    code = 2


class CliIOError(CliError):
    """A file that cannot be read or written: exit code 3."""

    code = 3


def _same(a: Path, b: Path) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_io(inputs=(), files=(), folders=()) -> None:
    """Refuse, before any computation, outputs that would destroy an input or cannot be written.

    Args:
        inputs: ``(option, path)`` of the files read (None skipped); each is protected with its
            JSON sidecar (``FILE.json``, see ``record.dataset.sidecar_path``).
        files: ``(option, path)`` of the files written (None skipped); a dataset CSV's sidecar
            is added by the caller. The folder must exist and be writable.
        folders: ``(option, path)`` of output folders; created if missing, must be writable.

    Raises CliError (an output is an input, an input's sidecar or another output) or
    CliIOError (folder missing or not writable, output is a folder or under a file).
    """
    protected = []
    for opt, p in inputs:
        if p is not None:
            p = Path(p)
            protected += [(p, f"the input {p}"),
                          (p.with_suffix(".json"), f"the sidecar of the input {p}")]
    seen: list[tuple[str, Path]] = []
    outs = [(o, Path(p), False) for o, p in files if p is not None] + \
           [(o, Path(p), True) for o, p in folders if p is not None]
    for opt, p, is_dir in outs:
        for q, what in protected:
            if _same(p, q):
                raise CliError(f"{opt}: {p} is {what}; refusing to overwrite it")
        for o2, q in seen:
            if _same(p, q):
                raise CliError(f"{opt}: {p} is also the output of {o2}")
        seen.append((opt, p))
        if is_dir:
            _check_folder(opt, p, create=True)
        else:
            if p.is_dir():
                raise CliIOError(f"{opt}: {p} is a folder, expected a file")
            _check_folder(opt, p.parent if str(p.parent) else Path("."), create=False)


def _check_folder(opt: str, d: Path, create: bool) -> None:
    try:
        writable_folder(d, create=create, what=opt)
    except FolderError as exc:
        raise CliIOError(str(exc)) from None


def parse_narx(text, option: str = "--narx", allow_none: bool = False):
    """(na, nb, nk) from "na,nb,nk" (or None for 'none'/'off' when ``allow_none``)."""
    if text is None:
        return None
    if allow_none and text.strip().lower() in ("none", "off", ""):
        return None
    try:
        return tuple(parse_orders(text, option))
    except ValueError as exc:
        raise CliError(str(exc)) from None


def write_json(path, obj) -> None:
    """Strict JSON (NaN/Inf as null), written atomically."""
    write_json_atomic(path, obj)


def add_validation_option(p, what: str) -> None:
    """``--validation {auto,per-type,last}``: which training records validate ``what``
    (evaluate.baselines.validation_records; one wording for identify and evaluate)."""
    p.add_argument("--validation", default="auto", choices=["auto", "per-type", "last"],
                   help=f"which {what}: per-type: the last record by file name of each "
                        f"trajectory type (the file name's prefix before '_'; cdam identify "
                        f"--model arx_kstep and cdam evaluate --baselines pick the same, so the "
                        f"same TRAIN gives the same ARX); last: the last record given; auto: "
                        f"per-type with --loader nanodrone, else last (default: auto)")


def validation_rule(args) -> str:
    """The rule ``--validation`` names (``auto`` resolved by the loader)."""
    if args.validation != "auto":
        return args.validation
    return "per-type" if args.loader == "nanodrone" else "last"
