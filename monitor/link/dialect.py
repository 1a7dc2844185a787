"""What the ardupilotmega dialect says about a message: its id, CRC extra, layout and time field.

Why a module of its own: the frame parser needs each id's CRC extra and payload struct, the signal map
needs to check ``MESSAGE.field[index]`` names and find where that value sits in the unpacked payload,
and the encoder needs the field order. All three read pymavlink's generated classes, never its parser.
"""

from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass
from dataclasses import field as dc_field
from functools import cache

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = [
    "mavlink",
    "MessageLayout",
    "layout_by_id",
    "layout_by_name",
    "known_layout",
    "mavlink1_length",
    "TIME_FIELDS",
]

# The fields that can stamp a message with its sampling instant, in order of preference, and their unit in us.
TIME_FIELDS: tuple[tuple[str, int], ...] = (("time_usec", 1), ("time_boot_ms", 1000))

_BY_NAME = {cls.msgname: cls for cls in mavlink.mavlink_map.values()}
_TOKEN = re.compile(r"(\d*)([a-zA-Z?])")


@dataclass(frozen=True)
class MessageLayout:
    """One message type: where each field's values sit in ``unpacker.unpack(payload)``."""

    msgid: int
    name: str
    crc_extra: int
    unpacker: struct.Struct
    fields: tuple[str, ...]  # wire order (pymavlink's ordered_fieldnames)
    offsets: dict[str, int]  # first flat position of each field in the unpacked tuple
    lengths: dict[str, int]  # values per field: N for numeric arrays, 1 for scalars and char arrays
    is_text: dict[str, bool]
    codes: dict[str, str] = dc_field(default_factory=dict)  # struct code of each field ('I': uint32, 'Q': uint64...)
    time_names: tuple[tuple[str, int], ...] = TIME_FIELDS  # DataFlash: TimeUS, TimeMS

    def wrap(self, field: str) -> int:
        """Units after which ``field`` wraps: 2^32 for a 32-bit time field (``time_boot_ms``, SERVO_OUTPUT_RAW's
        ``time_usec``), 0 for one that does not wrap in practice (64-bit)."""
        return 1 << 32 if self.codes.get(field) in ("I", "i") else 0

    def position(self, field: str, index: int = 0) -> int:
        """Flat position of ``field[index]``; ValueError naming what is wrong."""
        if field not in self.offsets:
            raise ValueError(f"{self.name} has no field '{field}' (fields: {', '.join(self.fields)})")
        if self.is_text[field]:
            raise ValueError(f"{self.name}.{field} is text, not a number")
        if not 0 <= index < self.lengths[field]:
            size = self.lengths[field]
            raise ValueError(f"{self.name}.{field}[{index}] is out of range ({size} value{'s' * (size > 1)})")
        return self.offsets[field] + index

    def time_field(self) -> tuple[str, int] | None:
        """(field, microseconds per unit) of the field that stamps this message's instant, if any."""
        for name, unit_us in self.time_names:
            if name in self.offsets:
                return name, unit_us
        return None

    def decode(self, payload: bytes) -> tuple:
        """All values of a payload (MAVLink 2 strips trailing zero bytes: they are put back)."""
        unpacker = self.unpacker
        if len(payload) < unpacker.size:
            payload = bytes(payload).ljust(unpacker.size, b"\x00")
        return unpacker.unpack_from(payload)


def _build(cls) -> MessageLayout:
    fmt = cls.unpacker.format
    tokens = _TOKEN.findall(fmt[1:] if fmt[0] in "<>=!@" else fmt)
    offsets: dict[str, int] = {}
    lengths: dict[str, int] = {}
    is_text: dict[str, bool] = {}
    codes: dict[str, str] = {}
    flat = 0
    for name, (count, code) in zip(cls.ordered_fieldnames, tokens, strict=True):
        text = code == "s"
        n = 1 if text else int(count or 1)
        offsets[name], lengths[name], is_text[name], codes[name] = flat, n, text, code
        flat += n
    return MessageLayout(
        cls.id,
        cls.msgname,
        cls.crc_extra,
        cls.unpacker,
        tuple(cls.ordered_fieldnames),
        offsets,
        lengths,
        is_text,
        codes,
    )


@cache
def layout_by_id(msgid: int) -> MessageLayout | None:
    cls = mavlink.mavlink_map.get(msgid)
    return _build(cls) if cls is not None else None


def layout_by_name(name: str) -> MessageLayout | None:
    cls = _BY_NAME.get(name.upper())
    return layout_by_id(cls.id) if cls is not None else None


def known_layout(name: str) -> MessageLayout:
    """``layout_by_name`` for a message the dialect defines (the monitor's own messages): KeyError otherwise."""
    layout = layout_by_name(name)
    if layout is None:
        raise KeyError(f"the MAVLink dialect has no message {name}")
    return layout


@cache
def mavlink1_length(msgid: int) -> int | None:
    """The payload length of ``msgid`` in a MAVLink 1 frame (its base fields; None if v1 cannot carry it).

    Why pymavlink's v1 dialect: a MAVLink 1 payload stops before the extension fields (as the C library
    and pymavlink's v1 encoder send it), and only the v1 module's structs say where the base fields end.
    Imported on first use: only a link that answers a MAVLink 1 peer pays for it.
    """
    if msgid > 255:
        return None
    from pymavlink.dialects.v10 import ardupilotmega as v1

    cls = v1.mavlink_map.get(msgid)
    return cls.unpacker.size if cls is not None else None
