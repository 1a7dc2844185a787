"""PX4's on-board flight logs (ULog, ``.ulg``), read by pyulog, PX4's own parser.

Why pyulog and not a reader of our own: the format nests message definitions (``F`` records whose fields may
be other messages), appends data after a crash, marks dropouts and has grown flag bits over the years; PX4's
tools and Flight Review read it with pyulog, so the project reads what they read. This module turns a parsed
log into what the link layer already consumes, exactly as ``monitor.link.dataflash`` does for ArduPilot's
logs: ``(topic name, values in the topic's field order, timestamp)`` in time order.

* the signal map names topics and fields (``vehicle_angular_velocity.xyz[1]``, ``actuator_servos.control[1]``),
  checked against the log's own message formats (``ULogLayouts``: same syntax, scale and offset as MAVLink);
* a multi-instance topic is addressed by its instance: ``actuator_outputs[1].output[2]`` (instance 1;
  ``actuator_outputs`` is instance 0);
* every topic's ``timestamp`` (microseconds since boot) is its time field and the log's clock: the
  ``SampleAssembler`` joins the parts of a sample as it joins MAVLink parts, the instant topic's ``timestamp``
  being the sample's instant. Topics logged at different rates (PX4 logs ``vehicle_local_position`` at 10 Hz,
  ``vehicle_angular_velocity`` at 50 Hz) are joined as latest values with ``hold`` (``monitor.link.signals``);
* the inventory lists every topic instance with its count and rate (``log holds:``).

A ULog log is one vehicle's; its samples are filed under system id 1 (or ``--sysid N``), as a DataFlash log's.
pyulog reads the whole log into arrays (one pass); a 100 MB log takes seconds.
"""

from __future__ import annotations

import contextlib
import io
import logging
import re
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from monitor.errors import UserError
from monitor.link.dialect import MessageLayout
from monitor.link.log_inventory import LogInventory
from monitor.link.signals import Layouts

_logger = logging.getLogger(__name__)

__all__ = ["ULOG_MAGIC", "ULogLayouts", "ULogLog", "is_ulog", "open_ulog", "topic_name"]

ULOG_MAGIC = b"ULog\x01\x12\x35"  # the file header's first 7 bytes (the format's magic)
_TIME = (("timestamp", 1),)
_ELEMENT = re.compile(r"^(.+)\[(\d+)\]$")  # pyulog flattens arrays: ``xyz[0]``, ``xyz[1]``, ...
_INSTANCE = re.compile(r"^([A-Za-z0-9_]+)(?:\[(\d+)\])?$")
_CODES = {
    "int8_t": "b",
    "uint8_t": "B",
    "int16_t": "h",
    "uint16_t": "H",
    "int32_t": "i",
    "uint32_t": "I",
    "int64_t": "q",
    "uint64_t": "Q",
    "float": "f",
    "double": "d",
    "bool": "?",
    "char": "c",
}
_HINT = (
    "a ULog log names PX4's topics: give a signal map of them with --signals FILE (a PX4 fixed-wing's, alpha "
    "derived from velocity and attitude, is in docs/tutorials/px4.md)"
)


def is_ulog(path: str | Path) -> bool:
    """Whether the file starts with the ULog header (whatever its name)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(ULOG_MAGIC)) == ULOG_MAGIC
    except OSError:
        return False


def topic_name(name: str, multi_id: int) -> str:
    """How a signal map names a topic instance: ``actuator_outputs`` (instance 0), ``actuator_outputs[1]``."""
    return name if multi_id == 0 else f"{name}[{multi_id}]"


def _layout(name: str, msg_id: int, field_data: list) -> MessageLayout:
    """A topic's fields as the link layer's ``MessageLayout``: pyulog's flattened ``base[i]`` grouped back into
    arrays (``xyz`` of 3), nested fields (``esc[0].esc_rpm``) kept as named scalars."""
    fields: list[str] = []
    offsets: dict[str, int] = {}
    lengths: dict[str, int] = {}
    is_text: dict[str, bool] = {}
    codes: dict[str, str] = {}
    for flat, f in enumerate(field_data):
        match = _ELEMENT.match(f.field_name)
        base = match.group(1) if match and "." not in match.group(1) else f.field_name
        if base not in offsets:
            fields.append(base)
            offsets[base] = flat
            lengths[base] = 0
            codes[base] = _CODES.get(f.type_str, "?")
            is_text[base] = f.type_str == "char"
        lengths[base] += 1
    return MessageLayout(msg_id, name, 0, struct.Struct("<"), tuple(fields), offsets, lengths, is_text, codes, _TIME)


class ULogLayouts(Layouts):
    """The log's own topics, as the signal map looks them up (``timestamp`` the time field)."""

    kind = "ULog"
    instant_field = "timestamp"

    def __init__(self, datasets: dict[str, Any]) -> None:
        self._datasets = datasets  # topic name (``topic`` or ``topic[i]``) -> pyulog's Data
        self._cache: dict[str, MessageLayout] = {}

    def names(self) -> list[str]:
        return sorted(self._datasets)

    def __call__(self, name: str) -> MessageLayout | None:
        match = _INSTANCE.match(name)
        if match is None:
            return None
        key = topic_name(match.group(1), int(match.group(2) or 0))
        layout = self._cache.get(key)
        if layout is None:
            data = self._datasets.get(key)
            if data is None:
                return None
            layout = self._cache[key] = _layout(key, data.msg_id, data.field_data)
        return layout

    def unknown(self, name: str) -> str:
        names = self.names()
        shown = ", ".join(names[:40]) + (f" and {len(names) - 40} more" if len(names) > 40 else "")
        return f"unknown ULog topic '{name}' (this log's topics: {shown})"

    def no_map(self) -> str:
        return _HINT


class ULogLog:
    """One opened ULog log: its topics as layouts, its inventory, its records in time order.

    The same interface as ``monitor.link.dataflash.DataFlashLog`` (``layouts``, ``counts``, ``records``,
    ``inventory``, ``records_read``, ``close``), so ``analyse`` and ``identify`` read either the same way."""

    kind = "ulog"

    def __init__(self, path: str | Path, ulog: Any) -> None:
        self.path = str(path)
        self.ulog = ulog
        self.datasets = {topic_name(d.name, d.multi_id): d for d in ulog.data_list if len(d.data.get("timestamp", ()))}
        self.counts = {name: len(d.data["timestamp"]) for name, d in self.datasets.items()}
        self.layouts = ULogLayouts(self.datasets)
        self.inventory = self._inventory()
        self.records_read = 0

    def _inventory(self) -> LogInventory:
        inv = LogInventory(kind="ulog")
        for name, d in sorted(self.datasets.items()):
            stamps = d.data["timestamp"]
            inv.add_counts(name, len(stamps), int(stamps.min()), int(stamps.max()))
        # the log's span as pyulog and ulog_info give it (header start to last timestamp): a topic never published
        # has timestamp 0, which must not stretch it
        inv.first_us, inv.last_us = int(self.ulog.start_timestamp), int(self.ulog.last_timestamp)
        inv.dropouts = len(self.ulog.dropouts)
        return inv

    def records(self, wanted: dict[str, set[str]]) -> Iterator[tuple[str, tuple, int]]:
        """``(topic, values, t_us)`` of every record of the ``wanted`` topics in time order (stable: a topic's
        own order kept); ``values`` in the topic's field order, the wanted fields filled, the others 0.

        Records of several topics stamped alike come in the reverse order of ``wanted``, whose first topic is the
        instant (``wanted_fields``): a sample then sees every record stamped at its instant (pyulog keeps each
        topic's records apart, so the file's own interleaving of equal stamps is not known)."""
        import numpy as np

        plans = []
        for name, cols in reversed(wanted.items()):
            layout = self.layouts(name)
            if layout is None or layout.name not in self.datasets:
                continue
            data = self.datasets[layout.name]
            flat = [f.field_name for f in data.field_data]
            positions = sorted(
                {
                    layout.offsets[c] + i
                    for c in cols | {"timestamp"}
                    if c in layout.offsets
                    for i in range(layout.lengths[c])
                }
            )
            columns = np.column_stack([data.data[flat[p]].astype(np.float64) for p in positions])
            plans.append((layout.name, len(flat), positions, columns, data.data["timestamp"].astype(np.int64)))
        if not plans:
            return
        stamps = np.concatenate([p[4] for p in plans])
        which = np.concatenate([np.full(len(p[4]), i, dtype=np.int64) for i, p in enumerate(plans)])
        rows = np.concatenate([np.arange(len(p[4]), dtype=np.int64) for p in plans])
        order = np.argsort(stamps, kind="stable")
        for i in order.tolist():
            name, width, positions, columns, times = plans[which[i]]
            row = int(rows[i])
            values: list[Any] = [0] * width
            for pos, value in zip(positions, columns[row].tolist(), strict=True):
                values[pos] = value
            self.records_read += 1
            yield name, tuple(values), int(times[row])

    def close(self) -> None:
        """Nothing held open: pyulog read the file whole."""


def open_ulog(path: str | Path) -> ULogLog:
    """Parse a ULog log; anything pyulog cannot read is a one-line UserError."""
    if not is_ulog(path):
        raise UserError(f"{path}: not a ULog log (a .ulg starts with the bytes 'ULog' 01 12 35)")
    from pyulog import ULog

    complaints = io.StringIO()  # pyulog prints what it finds wrong on stdout, where it would corrupt --json
    try:
        with contextlib.redirect_stdout(complaints):
            ulog = ULog(str(path))
    except Exception as exc:  # pyulog raises ULogException, struct.error, ValueError... on a damaged header
        raise UserError(f"{path}: cannot read the ULog log: {exc}") from None
    lines = complaints.getvalue().strip().splitlines()
    if lines or ulog.file_corruption:
        more = f" (and {len(lines) - 1} more lines)" if len(lines) > 1 else ""
        what = lines[0][:200] if lines else "file corruption detected"
        _logger.warning("%s: pyulog: %s%s; the records around the damage are read", path, what, more)
    log = ULogLog(path, ulog)
    if not log.counts:
        raise UserError(f"{path}: the ULog log holds no data messages")
    return log
