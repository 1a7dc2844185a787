"""ArduPilot's on-board DataFlash logs (``.bin``, and their text form ``.log``), read by pymavlink's DFReader.

Why: an identification flight's high-rate attitude, servo outputs and angle of attack live in the autopilot's
own log, not in the telemetry. pymavlink parses the format (FMT records declare each message's name, struct
format and columns; DFReader applies the format's multipliers); this module turns its messages into what the
link layer already consumes, ``(message name, values in FMT column order, TimeUS)``:

* the signal map names DataFlash fields (``ATT.Pitch``, ``RATE.P``, ``AOA.AOA``, ``RCOU.C2``) and is checked
  against the log's own FMT records (``DataFlashLayouts``: same syntax, scale and offset as for MAVLink);
* ``TimeUS`` (``TimeMS`` in old logs) is every message's time field, so the ``SampleAssembler`` joins the parts
  of a sample exactly as it joins MAVLink parts, the instant message's ``TimeUS`` being the sample's instant;
* a message with an instance column (several IMUs or airspeed sensors) contributes its first instance only.

Only the messages the signal map names are read (DFReader's index skips the rest), and the inventory comes
from DFReader's per-message counts and each message's first and last TimeUS: a 100 MB log is not parsed whole.
pymavlink prints its complaints about damaged records on stdout and stderr, where they would corrupt
``--json``: they are caught and summarised in one WARNING. A DataFlash log is one vehicle's; its samples are
filed under system id 1 (or ``--sysid N``).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import struct
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.link.dialect import MessageLayout
from monitor.link.log_inventory import LogInventory
from monitor.link.signals import Layouts, SignalMap

__all__ = ["DATAFLASH_SYSID", "DataFlashLayouts", "DataFlashLog", "dataflash_kind", "open_dataflash", "wanted_fields"]

log = logging.getLogger(__name__)

DATAFLASH_SYSID = 1
_TIME_NAMES = (("TimeUS", 1), ("TimeMS", 1000))
_TEXT_CODES = set("nNZa")  # strings and the int16[32] array: not a signal
_CHUNK = 4096  # records read per call into pymavlink (its prints are caught around each call)
_HINT = (
    "a DataFlash log names its own messages: give a signal map of them with --signals FILE (ArduPlane's "
    "is in docs/tutorials/flight-logs.md, 'DataFlash logs')"
)


def dataflash_kind(path: str | Path) -> str | None:
    """``"binary"`` (starts with a record header 0xA3 0x95), ``"text"`` (a ``.log`` with FMT lines), else None."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8192)
    except OSError:
        return None
    if head[:2] == b"\xa3\x95":
        return "binary"
    if Path(path).suffix.lower() == ".log" and b"FMT," in head:
        return "text"
    return None


class DataFlashLayouts(Layouts):
    """The log's own messages, as the signal map looks them up (each column one value; TimeUS the time field)."""

    kind = "DataFlash"
    instant_field = "TimeUS"

    def __init__(self, formats: dict[str, Any], ids: dict[str, int]) -> None:
        self._formats = formats
        self._ids = ids
        self._cache: dict[str, MessageLayout] = {}

    def names(self) -> list[str]:
        return sorted(self._formats)

    def format_of(self, name: str) -> Any:
        """pymavlink's ``DFFormat`` of a message (its instance column, multipliers), or None."""
        return self._formats.get(name)

    def __call__(self, name: str) -> MessageLayout | None:
        layout = self._cache.get(name)
        if layout is None:
            fmt = self._formats.get(name)
            if fmt is None:
                return None
            cols = tuple(fmt.columns)
            codes = [chr(c) if isinstance(c, int) else c for c in fmt.msg_fmts]
            if len(codes) != len(cols):  # pymavlink reads such a record; its values could not be named
                raise UserError(
                    f"DataFlash log: the FMT record of {name} declares {len(codes)} fields but names {len(cols)}"
                    " columns (a corrupt log)"
                )
            layout = self._cache[name] = MessageLayout(
                self._ids.get(name, 0),
                name,
                0,
                struct.Struct(fmt.msg_struct),
                cols,
                {c: i for i, c in enumerate(cols)},
                {c: 1 for c in cols},
                {c: code in _TEXT_CODES for c, code in zip(cols, codes, strict=True)},
                dict(zip(cols, codes, strict=True)),
                _TIME_NAMES,
            )
        return layout

    def unknown(self, name: str) -> str:
        names = self.names()
        shown = ", ".join(names[:40]) + (f" and {len(names) - 40} more" if len(names) > 40 else "")
        return f"unknown DataFlash message '{name}' (this log's messages: {shown})"

    def no_map(self) -> str:
        return _HINT


@contextlib.contextmanager
def _quiet(sink: io.StringIO):
    """pymavlink's prints go to ``sink`` (never to our stdout, which may be carrying --json)."""
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        yield


@contextlib.contextmanager
def _quiet_fds(sink: io.StringIO):
    """Also what its compiled indexer writes to file descriptors 1 and 2 goes to ``sink`` (opening only)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile() as tmp:
        try:
            os.dup2(tmp.fileno(), 1)
            os.dup2(tmp.fileno(), 2)
            with _quiet(sink):
                yield
        finally:
            with contextlib.suppress(Exception):
                import ctypes

                ctypes.CDLL(None).fflush(None)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            tmp.seek(0)
            sink.write(tmp.read().decode("utf-8", "replace"))


def wanted_fields(smap: SignalMap, layouts: DataFlashLayouts) -> dict[str, set[str]]:
    """Message -> the columns a signal map reads from it (its time field included)."""
    out: dict[str, set[str]] = {}
    for name, field in [(smap.instant, None), *((s.message, s.field) for s in smap.raw.values())]:
        layout = layouts(name)
        stamp = layout.time_field() if layout is not None else None
        cols = out.setdefault(name, set())
        cols.update(c for c in (field, stamp[0] if stamp else None) if c)
    return out


class DataFlashLog:
    """One opened DataFlash log: its reader, its messages as layouts, its inventory."""

    def __init__(self, path: str | Path, kind: str, reader, complaints: io.StringIO) -> None:
        self.path = str(path)
        self.kind = kind
        self.reader = reader
        self._complaints = complaints
        if kind == "binary":
            ids = {name: t for t, name in reader.id_to_name.items()}
            self.counts = {name: reader.counts[t] for name, t in ids.items() if reader.counts[t] > 0}
            self._offsets = {name: reader.offsets[t] for name, t in ids.items() if reader.counts[t] > 0}
            formats = {f.name: f for f in reader.formats.values()}
        else:
            ids = dict(reader.name_to_id)
            self.counts = {name: n for name, n in reader.counts.items() if n > 0}
            self._offsets = {name: reader.offsets[name] for name in self.counts}
            formats = dict(reader.formats)
        self.layouts = DataFlashLayouts(formats, ids)
        self.inventory = self._inventory()
        self.records_read = 0

    def _time_at(self, offset: int) -> int | None:
        self.reader.offset = offset
        m = self.reader.recv_msg()
        for name, unit in _TIME_NAMES:
            value = getattr(m, name, None) if m is not None else None
            if value is not None:
                return int(value) * unit
        return None

    def _inventory(self) -> LogInventory:
        inv = LogInventory(kind="dataflash")
        with _quiet(self._complaints):
            for name, count in sorted(self.counts.items()):
                offsets = self._offsets[name]
                inv.add_counts(name, count, self._time_at(offsets[0]), self._time_at(offsets[-1]))
            self.reader.rewind()
        return inv

    def records(self, wanted: dict[str, set[str]]) -> Iterator[tuple[str, tuple, int]]:
        """``(name, values, t_us)`` of every record of the ``wanted`` messages, in the log's order; ``values`` in
        FMT column order, the wanted columns filled (multipliers applied), the others 0."""
        reader = self.reader
        plan: dict[str, tuple[int, list[tuple[int, str]], str | None, int, int]] = {}
        for name, cols in wanted.items():
            layout = self.layouts(name)
            if layout is None or name not in self.counts:
                continue
            stamp = layout.time_field()
            if stamp is None:
                continue
            fmt = self.layouts.format_of(name)
            plan[name] = (
                len(layout.fields),
                [(layout.offsets[c], c) for c in cols if c in layout.offsets],
                getattr(fmt, "instance_field", None),
                layout.offsets[stamp[0]],
                stamp[1],
            )
        if not plan:
            return
        types = list(plan)
        first_instance: dict[str, Any] = {}
        with _quiet(self._complaints):
            reader.rewind()
        done = False
        while not done:
            chunk: list[tuple[str, tuple, int]] = []
            with _quiet(self._complaints):
                for _ in range(_CHUNK):
                    m = reader.recv_match(type=types, strict=True)
                    if m is None:
                        done = True
                        break
                    name = m.get_type()
                    width, columns, instance_field, t_pos, unit_us = plan[name]
                    if instance_field is not None:
                        inst = getattr(m, instance_field, None)
                        if first_instance.setdefault(name, inst) != inst:
                            continue
                    values: list[Any] = [0] * width
                    for pos, col in columns:
                        values[pos] = getattr(m, col)
                    chunk.append((name, tuple(values), int(values[t_pos]) * unit_us))
            self.records_read += len(chunk)
            yield from chunk
        self.report_complaints()

    def report_complaints(self) -> None:
        """One WARNING with pymavlink's first complaint about the log (damaged records), if it had any."""
        text = self._complaints.getvalue().strip()
        if text:
            lines = text.splitlines()
            log.warning(
                "%s: pymavlink's DataFlash reader: %s%s",
                self.path,
                lines[0][:200],
                f" (and {len(lines) - 1} more lines)" if len(lines) > 1 else "",
            )
            self._complaints.seek(0)
            self._complaints.truncate()

    def close(self) -> None:
        close = getattr(self.reader, "close", None)
        if close is not None:
            with contextlib.suppress(Exception):
                close()


def open_dataflash(path: str | Path) -> DataFlashLog:
    """Open a DataFlash log (binary or text); anything that is not one is a one-line UserError."""
    kind = dataflash_kind(path)
    if kind is None:
        raise UserError(
            f"{path}: not a DataFlash log (a .bin starts with the record header 0xA3 0x95; a text .log holds FMT lines)"
        )
    from pymavlink import DFReader

    complaints = io.StringIO()
    try:
        with _quiet_fds(complaints):
            reader = DFReader.DFReader_binary(str(path)) if kind == "binary" else DFReader.DFReader_text(str(path))
    except Exception as exc:  # pymavlink raises bare Exceptions on a damaged FMT record
        raise UserError(f"{path}: cannot read the DataFlash log: {exc}") from None
    dlog = DataFlashLog(path, kind, reader, complaints)
    if not dlog.counts or set(dlog.counts) <= {"FMT"}:
        raise UserError(f"{path}: the DataFlash log holds no data records")
    return dlog
