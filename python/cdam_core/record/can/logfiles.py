"""Logging a CAN bus to python-can's standard log files and reading them back.

Writing uses ``can.Logger`` (the writer is chosen by suffix: candump ``.log``, ``.asc``,
``.blf``, ``.csv``, ...). The receive loop runs in the calling thread and flushes the writer at
least every ``flush_interval`` seconds (default 50 ms), so a logger killed with SIGKILL leaves a
text log complete up to at most one flush interval before the kill (page cache survives a
process kill; an ``fsync`` would only matter for a power loss). A kill may cut the last line:
``iter_log`` reports it; a bad line elsewhere is counted, named by its number and skipped. BLF is a compressed container
format: each flush closes a container (``BLFWriter`` keeps up to 128 KiB otherwise).
"""
from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Callable, Iterator

import can

__all__ = ["open_bus", "log_bus", "iter_log", "LOG_SUFFIXES", "UDP_GROUP"]

LOG_SUFFIXES = (".log", ".asc", ".blf", ".csv")
UDP_GROUP = "239.74.163.2"   # python-can's IPv4 default group for udp_multicast
INTERFACES = ("virtual", "slcan", "udp_multicast", "socketcan")


def open_bus(interface: str, channel: str | None = None, *, loopback_only: bool = True,
             receive_buffer: int = 32 * 1024 * 1024, bitrate: int = 1_000_000,
             port: int | None = None) -> can.BusABC:
    """Open a python-can bus.

    Args:
        interface: ``virtual``, ``slcan``, ``udp_multicast`` or ``socketcan``.
        channel: interface channel; for ``udp_multicast`` default the IPv4 group UDP_GROUP,
            for ``virtual`` default ``"cdam"``. ``slcan`` takes a serial port or
            ``socket://HOST:PORT`` (e.g. the QEMU board, TARGET.md) at ``bitrate``.
        loopback_only: for ``udp_multicast``, TTL 0 so that frames never leave this host.
        receive_buffer: for ``udp_multicast``, the socket receive buffer in bytes. The kernel's
            default (208 KiB) holds ~20 ms at 10 kframe/s, so a descheduled logger drops
            frames; like ``candump -r`` we ask for SO_RCVBUFFORCE (needs CAP_NET_ADMIN) and fall
            back to SO_RCVBUF (capped at net.core.rmem_max). 32 MiB holds a few seconds.
        port: for ``udp_multicast``, the UDP port (default python-can's 43113); a separate port
            keeps concurrent buses (e.g. parallel test runs) apart.
    """
    if interface not in INTERFACES:
        raise ValueError(f"interface: expected one of {', '.join(INTERFACES)}, got {interface!r}")
    if interface == "udp_multicast":
        bus = can.Bus(interface="udp_multicast", channel=channel or UDP_GROUP,
                      hop_limit=0 if loopback_only else 1, **({"port": port} if port else {}))
        sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
        if sock is not None and receive_buffer:
            _grow_receive_buffer(sock, int(receive_buffer))
        return bus
    if interface == "virtual":
        return can.Bus(interface="virtual", channel=channel or "cdam")
    if not channel:
        raise ValueError(f"channel: required for interface {interface!r}")
    if interface == "slcan":
        return can.Bus(interface="slcan", channel=channel, bitrate=bitrate)
    return can.Bus(interface="socketcan", channel=channel)


def _grow_receive_buffer(sock: socket.socket, size: int) -> int:
    force = getattr(socket, "SO_RCVBUFFORCE", 33)
    try:
        sock.setsockopt(socket.SOL_SOCKET, force, size)
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


def log_bus(bus: can.BusABC, path: str | Path, *, duration: float | None = None,
            listeners: list[Callable[[can.Message], None]] | None = None,
            flush_interval: float = 0.05, should_stop: Callable[[], bool] | None = None,
            on_start: Callable[[], None] | None = None) -> dict:
    """Receive from ``bus`` into the log file ``path`` until ``duration`` s or ``should_stop()``.

    Every received frame is also passed to each of ``listeners`` (e.g. a C610Recorder). The
    writer is flushed at least every ``flush_interval`` s and stopped (closed) on exit, also on
    KeyboardInterrupt. Returns ``{"frames": n, "seconds": s, "path": str}``.
    """
    path = Path(path)
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise ValueError(f"path: log suffix must be one of {', '.join(LOG_SUFFIXES)}, "
                         f"got {path.name!r}")
    if duration is not None and not duration > 0:
        raise ValueError(f"duration: expected a positive number of seconds, got {duration!r}")
    if not flush_interval > 0:
        raise ValueError(f"flush_interval: expected > 0, got {flush_interval!r}")
    listeners = list(listeners or [])
    writer = can.Logger(str(path))
    close_container = getattr(writer, "_flush", None) if path.suffix.lower() == ".blf" else None

    def flush() -> None:
        if close_container is not None:    # BLF: write the buffered objects as a container
            close_container()
        writer.file.flush()                 # then hand the bytes to the kernel
    n = 0
    start = time.monotonic()
    last_flush = start
    if on_start:
        on_start()
    try:
        running = True
        while running:
            # receive until the next flush is due, then flush and check the stop conditions
            while True:
                msg = bus.recv(timeout=0.02)
                if msg is not None:
                    writer(msg)
                    for fn in listeners:
                        fn(msg)
                    n += 1
                now = time.monotonic()
                if now - last_flush >= flush_interval:
                    break
            flush()
            last_flush = now
            if duration is not None and now - start >= duration:
                running = False
            if should_stop is not None and should_stop():
                running = False
    finally:
        writer.stop()
    return {"frames": n, "seconds": time.monotonic() - start, "path": str(path)}


class _Lines:
    """A text file's lines, numbered from 1, read one ahead (so ``at_end`` knows the last);
    ``push`` puts a line back in front (not counted)."""

    def __init__(self, f):
        self._f, self._pushed = f, []
        self._ahead = next(f, None)
        self.lineno, self.last = 0, ""

    def __iter__(self):
        return self

    def __next__(self) -> str:
        if self._pushed:
            return self._pushed.pop()
        if self._ahead is None:
            raise StopIteration
        self.last, self._ahead = self._ahead, next(self._f, None)
        self.lineno += 1
        return self.last

    @property
    def at_end(self) -> bool:
        return self._ahead is None

    def push(self, line: str) -> None:
        self._pushed.append(line)

    def close(self) -> None:   # python-can's reader.stop(); the file is closed by iter_log
        pass


_TEXT_READERS = {".log": can.CanutilsLogReader, ".asc": can.ASCReader, ".csv": can.CSVReader}
_ASC_STATE = ("base", "_converted_base", "start_time", "date", "timestamps_format",
              "relative_timestamp", "internal_events_logged")
MAX_LISTED_LINES = 20     # skipped lines listed with their reason in the report (all are counted)


def _text_frames(path: Path, report: dict) -> Iterator[can.Message]:
    """Frames of a text log; a line python-can cannot parse is recorded and skipped."""
    cls = _TEXT_READERS[path.suffix.lower()]
    with open(path, encoding="utf-8", errors="replace", newline=None) as f:
        lines = _Lines(f)
        reader = cls(lines)
        while True:
            it = iter(reader)
            try:
                for msg in it:
                    yield msg
                return
            except Exception as exc:  # noqa: BLE001 - any parse failure is one bad line
                reason = f"{type(exc).__name__}: {exc}"
                if lines.at_end and not lines.last.endswith("\n"):
                    report["truncated"] = f"line {lines.lineno}: {reason}"   # cut by a kill
                    return
                report["skipped_lines"] += 1
                if len(report["skipped"]) < MAX_LISTED_LINES:
                    report["skipped"].append({"line": lines.lineno, "reason": reason[:200]})
            # a new reader goes on with the next line; its header skip eats a blank line
            old, reader = reader, cls(lines)
            for name in _ASC_STATE if cls is can.ASCReader else ():
                setattr(reader, name, getattr(old, name))
            lines.push("")


def _blf_frames(path: Path, report: dict) -> Iterator[can.Message]:
    """Frames of a BLF file; a corrupt object ends the reading (a binary container has no lines
    to resume at) and is reported as ``truncated``."""
    reader = can.BLFReader(str(path))
    try:
        it = iter(reader)
        while True:
            try:
                msg = next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - partial last container after a kill
                report["truncated"] = f"{type(exc).__name__}: {exc}"
                return
            yield msg
    finally:
        reader.stop()


def iter_log(path: str | Path, report: dict | None = None) -> Iterator[can.Message]:
    """Frames of a python-can log file (format by suffix).

    Text logs (.log candump, .asc, .csv) are read line by line: a line that cannot be parsed
    (bad hex, a stray text line, bad base64) is counted and skipped, and reading goes on with
    the next one. The last line without its newline (a logger killed mid-write) is reported as
    ``truncated`` instead. A BLF file stops at its first corrupt object (``truncated``). Lines
    python-can's ASC reader ignores by design (comments, events) are not frames and not counted.

    ``report`` (if given) receives ``skipped_lines`` (count), ``skipped`` (the first
    MAX_LISTED_LINES as ``{"line": n, "reason": text}``, lines numbered from 1) and
    ``truncated`` (the error text, else False).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise ValueError(f"path: log suffix must be one of {', '.join(LOG_SUFFIXES)}, "
                         f"got {path.name!r}")
    rep = report if report is not None else {}
    rep.update(truncated=False, skipped_lines=0, skipped=[])
    if path.suffix.lower() == ".blf":
        yield from _blf_frames(path, rep)
    else:
        yield from _text_frames(path, rep)
