"""MAVLink telemetry logs (``.tlog``) as MAVProxy and QGroundControl write them: another byte source.

Each record is an 8-byte big-endian timestamp (microseconds since the Unix epoch) followed by one whole
MAVLink frame (v1 or v2, signed or not). The reader uses each frame's own length to find the next record;
a record that does not start with a frame is skipped one byte at a time (counted), so a damaged or
truncated log still yields every good record around the damage.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

from monitor.errors import UserError

__all__ = ["read_tlog", "TlogWriter", "TlogStats"]

_STAMP = struct.Struct(">Q")


class TlogStats:
    def __init__(self) -> None:
        self.records = 0
        self.skipped_bytes = 0
        self.truncated = False


def _frame_length(data: bytes, i: int, n: int) -> int | None:
    """Length of the frame starting at ``i`` (None if no frame starts there)."""
    if i + 1 >= n:
        return None
    stx = data[i]
    if stx == 0xFD:
        if i + 2 >= n:
            return None
        return 12 + data[i + 1] + (13 if data[i + 2] & 0x01 else 0)
    if stx == 0xFE:
        return 8 + data[i + 1]
    return None


def read_tlog(path: str | Path, stats: TlogStats | None = None) -> Iterator[tuple[int, bytes]]:
    """``(t_us, frame)`` for every record; the file is read whole (a 1-hour 50 Hz log is tens of MB)."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise UserError(f"{path}: cannot read the log: {exc.strerror or exc}") from None
    stats = stats if stats is not None else TlogStats()
    i, n = 0, len(data)
    unpack = _STAMP.unpack_from
    while i + 8 < n:
        length = _frame_length(data, i + 8, n)
        if length is None:
            stats.skipped_bytes += 1
            i += 1
            continue
        end = i + 8 + length
        if end > n:
            stats.truncated = True
            return
        stats.records += 1
        yield unpack(data, i)[0], data[i + 8 : end]
        i = end
    if i < n:
        stats.truncated = True


class TlogWriter:
    """Append records the way MAVProxy does (tests and benchmarks write logs of flights nobody flew)."""

    def __init__(self, path: str | Path) -> None:
        self._fh = open(path, "wb")

    def write(self, t_us: int, frame: bytes) -> None:
        self._fh.write(_STAMP.pack(t_us) + frame)

    def write_datagram(self, t_us: int, data: bytes) -> int:
        """One record per frame of a datagram (a vehicle may pack several), as a ground station logs messages.

        Bytes that do not start a whole frame are written as one record of their own, so nothing received is
        dropped; the reader skips them and counts them. Returns the number of records written.
        """
        i, n, records = 0, len(data), 0
        while i < n:
            length = _frame_length(data, i, n)
            end = i + length if length is not None and i + length <= n else n
            self.write(t_us, data[i:end])
            i, records = end, records + 1
        return records

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
