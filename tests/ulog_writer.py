"""A ULog writer from the format's own specification (docs.px4.io, "ULog File Format"), for logs of flights
nobody flew on PX4: tests write them and read them back with pyulog (which proves them valid) and with the
project.

Why not pyulog's writer: pyulog 1.3's ``ULog.write_ulog`` writes back a log it parsed, from its private state;
building that state by hand would be writing against pyulog's internals. The format is short:

* header (16 bytes): the magic ``ULog`` 01 12 35, version 1, the uint64 start time (us);
* then messages, each ``uint16 size, uint8 type`` and ``size`` bytes: first the flag bits ``B`` (8 compat, 8
  incompat flag bytes, 3 uint64 appended offsets), then the definitions (``F``: ``name:type field;...``, ``I``:
  ``uint8 key length, "type name", value``), then the data section: ``A`` subscribes a topic instance
  (``uint8 multi_id, uint16 msg_id, name``) and ``D`` carries one record (``uint16 msg_id`` and the fields,
  packed little-endian in the format's order).
"""

from __future__ import annotations

import struct
from pathlib import Path

__all__ = ["ULogWriter"]

_CODES = {"uint64_t": "Q", "int64_t": "q", "uint32_t": "I", "int32_t": "i", "uint16_t": "H", "int16_t": "h"}
_CODES |= {"uint8_t": "B", "int8_t": "b", "float": "f", "double": "d", "bool": "?"}


def _message(kind: str, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), ord(kind)) + payload


class ULogWriter:
    """``topics``: name -> [(type, field), ...] with ``float[4]`` style arrays; ``timestamp`` first by convention."""

    def __init__(self, path: Path, start_us: int, topics: dict[str, list[tuple[str, str]]], info: dict[str, str]):
        self._fh = open(path, "wb")
        self._fh.write(b"ULog\x01\x12\x35" + bytes((1,)) + struct.pack("<Q", start_us))
        self._fh.write(_message("B", bytes(16) + struct.pack("<3Q", 0, 0, 0)))
        for key, value in info.items():
            name = f"char[{len(value.encode())}] {key}".encode()
            self._fh.write(_message("I", bytes((len(name),)) + name + value.encode()))
        self._structs: dict[str, struct.Struct] = {}
        for name, fields in topics.items():
            text = name + ":" + "".join(f"{t} {f};" for t, f in fields)
            self._fh.write(_message("F", text.encode()))
            codes = ""
            for t, _f in fields:
                base, _, count = t.partition("[")
                codes += (count.rstrip("]") or "") + _CODES[base]
            self._structs[name] = struct.Struct("<" + codes)
        self._ids: dict[tuple[str, int], tuple[int, struct.Struct]] = {}

    def subscribe(self, topic: str, multi_id: int = 0) -> None:
        msg_id = len(self._ids)
        self._ids[(topic, multi_id)] = (msg_id, self._structs[topic])
        self._fh.write(_message("A", struct.pack("<BH", multi_id, msg_id) + topic.encode()))

    def write(self, topic: str, values: list, multi_id: int = 0) -> None:
        """One record: ``values`` flat, in the format's order (an array's elements in turn)."""
        msg_id, packer = self._ids[(topic, multi_id)]
        self._fh.write(_message("D", struct.pack("<H", msg_id) + packer.pack(*values)))

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> ULogWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
