"""What every command shares: the user-error type, order parsing, JSON output."""
from __future__ import annotations

from cdam_core.base.jsonio import write_json_atomic
from cdam_core.base.orders import parse_orders

__all__ = ["CliError", "parse_narx", "write_json"]


class CliError(Exception):
    """A user error: printed as 'cdam COMMAND: error: ...' with exit code 2, no traceback."""


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
