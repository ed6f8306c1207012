"""Logging a CAN bus to python-can's standard log files and reading them back.

Writing uses ``can.Logger`` (the writer is chosen by suffix: candump ``.log``, ``.asc``,
``.blf``, ``.csv``, ...). The receive loop runs in the calling thread and flushes the writer at
least every ``flush_interval`` seconds (default 50 ms), so a logger killed with SIGKILL leaves a
text log complete up to at most one flush interval before the kill (page cache survives a
process kill; an ``fsync`` would only matter for a power loss). A kill may cut the last line:
``iter_log`` reports it; a bad line elsewhere is counted, named by its number and skipped. BLF is
a compressed container format: each flush closes a container (``BLFWriter`` keeps up to 128 KiB
otherwise); a bad object or container is counted, skipped and reading goes on at the next.
"""
from __future__ import annotations

import socket
import struct
import time
import zlib
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


# BLF framing (python-can's can.io.blf, after Toby Lorenz' vector_blf): a file header, then
# objects, each a 16-byte base header (b"LOBJ", header size, header version, object size, type)
# and its body, padded to 4 bytes. The frames are objects inside LOG_CONTAINER objects (zlib,
# whose checksum covers the container, or uncompressed); an object may continue from one
# container into the next. A size field is what frames everything, so a bad one is found by the
# checks below and reading resumes at the next b"LOBJ" signature.
MAX_BLF_OBJECT = 1 << 20      # an inner object claiming more than 1 MiB has a corrupt size field
_SCAN_CHUNK = 1 << 20


class _TolerantBLF:
    """Frames of a BLF file; a bad object or container is counted, skipped and reading goes on
    at the next object (``report``: ``skipped_objects``, ``skipped_bytes``, ``skipped`` with
    byte offsets; ``truncated`` when the file ends inside an object)."""

    def __init__(self, path: Path, report: dict):
        from can.io import blf
        self.blf, self.report, self.path = blf, report, path
        try:
            self.reader = can.BLFReader(str(path))
        except (blf.BLFParseError, struct.error) as exc:
            raise ValueError(f"{path}: not a BLF file (file header: "
                             f"{type(exc).__name__}: {exc or 'bad signature'})") from None
        self.f = self.reader.file
        self.size = path.stat().st_size
        self.f.seek(0)
        head = blf.FILE_HEADER_STRUCT.unpack(self.f.read(blf.FILE_HEADER_STRUCT.size))
        if not blf.FILE_HEADER_STRUCT.size <= head[1] <= self.size:
            self.reader.stop()
            raise ValueError(f"{path}: not a BLF file (file header size {head[1]})")
        self.f.seek(head[1])
        self.tail = b""

    def _bad(self, offset: int, reason: str, nbytes: int) -> None:
        rep = self.report
        rep["skipped_objects"] += 1
        rep["skipped_bytes"] += int(nbytes)
        if len(rep["skipped"]) < MAX_LISTED_LINES:
            rep["skipped"].append({"offset": int(offset), "reason": reason[:200]})

    def _next_container(self, start: int) -> int | None:
        """File offset of the next plausible container header at or after ``start``."""
        base = self.blf.OBJ_HEADER_BASE_STRUCT
        pos = start
        while pos < self.size:
            self.f.seek(pos)
            chunk = self.f.read(_SCAN_CHUNK + base.size)
            k = chunk.find(b"LOBJ")
            while k >= 0:
                if k + base.size <= len(chunk):
                    _, hsize, _, osize, typ = base.unpack_from(chunk, k)
                    if typ == self.blf.LOG_CONTAINER and hsize >= base.size and \
                            base.size + self.blf.LOG_CONTAINER_STRUCT.size <= osize <= \
                            self.size - (pos + k):
                        return pos + k
                k = chunk.find(b"LOBJ", k + 1)
            pos += _SCAN_CHUNK
        return None

    def _resume(self, at: int, reason: str) -> bool:
        """Skip from ``at`` to the next container; False at the end of the file."""
        nxt = self._next_container(at + 4)
        self._bad(at, reason, (self.size if nxt is None else nxt) - at)
        if self.tail:
            self._bad(at, "object cut by the skipped bytes", len(self.tail))
            self.tail = b""
        if nxt is None:
            return False
        self.f.seek(nxt)
        return True

    def __iter__(self) -> Iterator[can.Message]:
        blf, f = self.blf, self.f
        base, cont = blf.OBJ_HEADER_BASE_STRUCT, blf.LOG_CONTAINER_STRUCT
        while True:
            at = f.tell()
            head = f.read(base.size)
            if not head:
                break
            if len(head) < base.size:
                self.report["truncated"] = f"byte {at}: partial object header"
                break
            sig, _, _, osize, typ = base.unpack(head)
            if sig != b"LOBJ" or osize < base.size + (cont.size if typ == blf.LOG_CONTAINER
                                                       else 0):
                if self._resume(at, f"bad object header (signature {sig!r}, size {osize})"):
                    continue
                break
            body = f.read(osize - base.size)
            if len(body) < osize - base.size:
                if self._next_container(at + 4) is None:     # the end: cut by a kill
                    self.report["truncated"] = f"byte {at}: object of {osize} bytes cut at " \
                                               f"{len(body) + base.size}"
                    break
                f.seek(at + base.size)
                if self._resume(at, f"object size {osize} runs past the next object"):
                    continue
                break
            f.read(osize % 4)                                 # padding
            if typ != blf.LOG_CONTAINER:
                continue
            method, _ = cont.unpack_from(body)
            payload = body[cont.size:]
            try:
                if method == blf.NO_COMPRESSION:
                    data = payload
                elif method == blf.ZLIB_DEFLATE:
                    z = zlib.decompressobj()
                    data = z.decompress(payload)
                    if not z.eof:
                        raise zlib.error("compressed stream incomplete")
                else:
                    raise zlib.error(f"unknown compression method {method}")
            except zlib.error as exc:
                if self._resume(at, f"container: {exc}"):
                    continue
                break
            yield from self._objects(self.tail + data, at)
            if method == blf.ZLIB_DEFLATE and z.unused_data:  # its size ran into the next one
                nxt = self._next_container(at + 4)
                if nxt is not None and nxt < f.tell():
                    self._bad(at, f"container size {osize} runs into the next container "
                                  f"(its stream read whole; resumed there)", 0)
                    f.seek(nxt)
        if self.tail and not self.report["truncated"]:
            self.report["truncated"] = f"the file ends inside an object ({len(self.tail)} bytes)"

    def _objects(self, data: bytes, at: int) -> Iterator[can.Message]:
        """The frames of one container's objects (after the previous container's tail); the
        last, incomplete object becomes the tail."""
        blf = self.blf
        base = blf.OBJ_HEADER_BASE_STRUCT
        pos, n = 0, len(data)
        self.tail = b""
        while pos < n:
            j = data.find(b"LOBJ", pos, pos + 8)            # after up to 7 padding bytes
            if j < 0:
                if pos + 8 > n:
                    self.tail = data[pos:]
                    return
                k = data.find(b"LOBJ", pos + 1)
                self._bad(at, "container: no object where one should start",
                          (n if k < 0 else k) - pos)
                if k < 0:
                    return
                pos = k
                continue
            if j + base.size > n:
                self.tail = data[j:]
                return
            _, hsize, hver, osize, _ = base.unpack_from(data, j)
            ext = {1: blf.OBJ_HEADER_V1_STRUCT.size, 2: blf.OBJ_HEADER_V2_STRUCT.size}.get(hver)
            if ext is None or hsize != base.size + ext or not \
                    base.size + ext <= osize <= MAX_BLF_OBJECT:
                k = data.find(b"LOBJ", j + 4)
                self._bad(at, f"container: bad object header (version {hver}, header size "
                              f"{hsize}, object size {osize})", (n if k < 0 else k) - j)
                if k < 0:
                    return
                pos = k
                continue
            if j + osize > n:                               # continues in the next container
                self.tail = data[j:]
                return
            try:
                yield from list(self.reader._parse_data(data[j:j + osize]))
            except (struct.error, blf.BLFParseError, ValueError) as exc:
                self._bad(at, f"container: bad object ({type(exc).__name__}: {exc})", osize)
            pos = j + osize


def _blf_frames(path: Path, report: dict) -> Iterator[can.Message]:
    """Frames of a BLF file (:class:`_TolerantBLF`)."""
    reader = _TolerantBLF(path, report)
    try:
        yield from reader
    finally:
        reader.reader.stop()


def iter_log(path: str | Path, report: dict | None = None) -> Iterator[can.Message]:
    """Frames of a python-can log file (format by suffix).

    Text logs (.log candump, .asc, .csv) are read line by line: a line that cannot be parsed
    (bad hex, a stray text line, bad base64) is counted and skipped, and reading goes on with
    the next one. The last line without its newline (a logger killed mid-write) is reported as
    ``truncated`` instead. A BLF file is read object by object: a bad object, or a container
    whose zlib stream fails its checksum, is counted and skipped, and reading goes on at the next
    object (a skipped container's frames cannot be counted: its bytes are); an uncompressed
    container has no checksum, so a damaged frame body inside one is read as it stands. Lines
    python-can's ASC reader ignores by design (comments, events) are not frames and not counted.

    ``report`` (if given) receives ``skipped_lines`` (count), ``skipped_objects`` and
    ``skipped_bytes`` (BLF), ``skipped`` (the first MAX_LISTED_LINES as ``{"line": n,
    "reason": text}``, lines numbered from 1, or ``{"offset": byte, "reason": text}`` for BLF)
    and ``truncated`` (the error text, else False).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise ValueError(f"path: log suffix must be one of {', '.join(LOG_SUFFIXES)}, "
                         f"got {path.name!r}")
    rep = report if report is not None else {}
    rep.update(truncated=False, skipped_lines=0, skipped_objects=0, skipped_bytes=0, skipped=[])
    if path.suffix.lower() == ".blf":
        yield from _blf_frames(path, rep)
    else:
        yield from _text_frames(path, rep)
