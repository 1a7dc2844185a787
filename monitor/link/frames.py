"""Bytes -> MAVLink frames, and the monitor's own frames -> bytes.

Why not pymavlink's parser on the hot path: it is a pure-Python state machine that builds a message
object per frame, most of the monitor's per-sample cost. This parser does the same job with ``struct``
and a C CRC (``fastcrc``): it finds each frame, checks its CRC with the message's CRC extra (and its
signature, with ``signing.Signer``), and hands out ``(msgid, sysid, compid, payload)``; the signal map
unpacks only the messages it uses. ``tests/test_link_frames.py`` checks it against pymavlink's encoder
and parser, byte for byte.

Streams and datagrams differ in one rule only. On a stream (TCP, serial, a tlog's byte stream) a frame
may be split anywhere, so the bytes after the last whole frame are kept for the next read. A datagram
holds whole frames, so bytes left at its end are a truncated frame: counted and dropped, never allowed
to swallow the start of the next datagram. Junk between frames is skipped to the next start byte
(counted once per run of junk); a frame with a bad CRC is skipped one byte at a time, because its
length byte may be junk too.

MAVLink 1 frames (``0xFE len seq sys comp msgid payload crc``; telemetry radios, older firmware, years of
archived tlogs) are read like MAVLink 2 ones: the one-byte message id, the CRC with the same CRC extra, the
payload handed out as it came. A v1 payload is never truncated but stops at the message's last base field
(v1 carries no extension fields); a v2 payload may have lost its trailing zero bytes. Both are shorter than
the dialect's struct, and ``MessageLayout.decode`` pads both with zeros, which is what pymavlink does.
MAVLink 1 cannot be signed, so a signed link refuses every v1 frame (counted ``v1_refused``). A v1 frame
whose message id the dialect does not know has no CRC extra to check: it cannot be told from junk.
``version`` is the protocol of the last frame handed out: the link answers a peer in the version it
speaks (``FrameEncoder(version=1)``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

from monitor.link.dialect import MessageLayout, layout_by_id, mavlink, mavlink1_length
from monitor.link.signing import SIGNATURE_LEN, Signer

if TYPE_CHECKING:
    from typing_extensions import Buffer  # collections.abc.Buffer from Python 3.12

__all__ = ["RawFrame", "FrameCounters", "FrameParser", "FrameEncoder", "crc16"]

try:
    from fastcrc.crc16 import mcrf4xx as crc16
except ImportError:  # pymavlink's own (slower, same result)

    def crc16(data: Buffer, initial: int | None = None) -> int:
        crc = mavlink.x25crc()
        if initial is not None:
            crc.crc = initial
        crc.accumulate(bytes(data))
        return crc.crc


_STX2 = 0xFD
_STX1 = 0xFE
_HEADER2 = 10
_HEADER1 = 6
_SIGNED = 0x01
MAX_FRAME = _HEADER2 + 255 + 2 + SIGNATURE_LEN

# (msgid, sysid, compid, payload)
RawFrame = tuple[int, int, int, bytes]


@dataclass
class FrameCounters:
    """What arrived that was not a usable frame, by cause."""

    frames: int = 0
    frames_v1: int = 0  # of ``frames``, those in MAVLink 1
    garbage: int = 0  # runs of bytes that are no frame, and frames with a bad CRC
    truncated: int = 0  # datagrams that ended inside a frame
    bad_signature: int = 0  # unsigned, wrongly signed or replayed frames (signed links only)
    wrong_dialect: int = 0  # MAVLink 2 message ids unknown to ardupilotmega
    v1_refused: int = 0  # valid MAVLink 1 frames on a signed link (v1 cannot be signed)

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class FrameParser:
    """One byte source's parser: ``feed`` returns the whole, valid frames found so far."""

    __slots__ = ("counters", "signer", "stream", "version", "_buf", "_crc_extra")

    def __init__(self, counters: FrameCounters, signer: Signer | None = None, stream: bool = False) -> None:
        self.counters = counters
        self.signer = signer
        self.stream = stream
        self.version = 0  # MAVLink version of the last frame handed out (0: none yet)
        self._buf = b""
        self._crc_extra: dict[int, bytes] = {}

    def _extra(self, msgid: int) -> bytes | None:
        extra = self._crc_extra.get(msgid)
        if extra is None:
            layout = layout_by_id(msgid)
            if layout is None:
                return None
            extra = self._crc_extra[msgid] = bytes((layout.crc_extra,))
        return extra

    def feed(self, data: bytes) -> list[RawFrame]:
        if self._buf:
            data = self._buf + data
            self._buf = b""
        elif self.signer is None and _HEADER2 + 2 < len(data) == _HEADER2 + 2 + data[1] and data[0] == _STX2:
            # the common datagram: one MAVLink 2 frame, exactly (routers send one message per datagram)
            msgid = data[7] | data[8] << 8 | data[9] << 16
            extra = self._crc_extra.get(msgid) or self._extra(msgid)
            if not data[2] and extra is not None and crc16(extra, crc16(data[1:-2])) == data[-2] | data[-1] << 8:
                self.counters.frames += 1
                self.version = 2
                return [(msgid, data[5], data[6], data[_HEADER2:-2])]
        out: list[RawFrame] = []
        c = self.counters
        i, n = 0, len(data)
        in_junk = False
        while i < n:
            stx = data[i]
            if stx != _STX2 and stx != _STX1:
                if not in_junk:
                    c.garbage += 1
                    in_junk = True
                j2, j1 = data.find(b"\xfd", i + 1), data.find(b"\xfe", i + 1)
                i = min(j for j in (j2, j1, n) if j >= 0)
                continue
            if stx == _STX1:
                end = i + _HEADER1 + data[i + 1] + 2 if i + 1 < n else n + 1
                if end > n:
                    break
                extra = self._extra(data[i + 5])
                if (
                    extra is not None
                    and crc16(extra, crc16(data[i + 1 : end - 2])) == data[end - 2] | data[end - 1] << 8
                ):
                    if self.signer is not None:
                        c.v1_refused += 1
                    else:
                        c.frames += 1
                        c.frames_v1 += 1
                        self.version = 1
                        out.append((data[i + 5], data[i + 3], data[i + 4], data[i + _HEADER1 : end - 2]))
                    i, in_junk = end, False
                else:
                    if not in_junk:
                        c.garbage += 1
                        in_junk = True
                    i += 1
                continue
            if n - i < _HEADER2:
                break
            mlen, incompat = data[i + 1], data[i + 2]
            signed = incompat & _SIGNED
            end = i + _HEADER2 + mlen + 2
            total_end = end + SIGNATURE_LEN if signed else end
            if incompat & ~_SIGNED:  # an incompatibility flag we do not know: not a frame we may read
                if not in_junk:
                    c.garbage += 1
                    in_junk = True
                i += 1
                continue
            if total_end > n:
                break
            msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
            extra = self._extra(msgid)
            if extra is None:
                c.wrong_dialect += 1
                i, in_junk = total_end, False
                continue
            if crc16(extra, crc16(data[i + 1 : end - 2])) != data[end - 2] | data[end - 1] << 8:
                if not in_junk:
                    c.garbage += 1
                    in_junk = True
                i += 1
                continue
            in_junk = False
            sysid, compid = data[i + 5], data[i + 6]
            if self.signer is not None and not (signed and self.signer.verify(data[i:total_end], sysid, compid)):
                c.bad_signature += 1
            else:
                c.frames += 1
                self.version = 2
                out.append((msgid, sysid, compid, data[i + _HEADER2 : end - 2]))
            i = total_end
        if i < n:
            if self.stream:
                self._buf = data[i:]
            else:
                c.truncated += 1
        return out


_HEADER_STRUCT = struct.Struct("<BBBBBBBHB")
_HEADER1_STRUCT = struct.Struct("<BBBBBB")
_CRC = struct.Struct("<H")


class FrameEncoder:
    """The monitor's outgoing frames on one link: its own sequence numbers, signed when a key is set.

    Byte-identical to pymavlink's encoder for the same message, sequence and ids (tested), without
    building pymavlink message objects on the hot path. ``version=1`` writes MAVLink 1 frames for a peer
    that speaks only v1 (a message whose id is above 255 still goes out in v2: v1 cannot carry it); a
    signed link never writes v1, which cannot be signed.
    """

    def __init__(self, sysid: int, compid: int, signer: Signer | None = None, version: int = 2) -> None:
        if version not in (1, 2):
            raise ValueError(f"MAVLink version must be 1 or 2, got {version}")
        if version == 1 and signer is not None:
            raise ValueError("MAVLink 1 frames cannot be signed")
        self.sysid = sysid
        self.compid = compid
        self.signer = signer
        self.version = version
        self.seq = 0
        self._incompat = _SIGNED if signer else 0

    def encode(self, layout: MessageLayout, values: tuple) -> bytes:
        """A frame of ``layout`` whose payload is ``layout.unpacker.pack(*values)`` (wire order, arrays flat)."""
        msgid = layout.msgid
        v1_length = mavlink1_length(msgid) if self.version == 1 else None
        seq = self.seq
        self.seq = (seq + 1) & 0xFF
        if v1_length is not None:  # MAVLink 1: the base fields, never truncated
            payload = layout.unpacker.pack(*values)[:v1_length]
            frame = _HEADER1_STRUCT.pack(_STX1, len(payload), seq, self.sysid, self.compid, msgid) + payload
        else:
            payload = layout.unpacker.pack(*values).rstrip(b"\x00") or b"\x00"  # MAVLink 2 truncation
            frame = (
                _HEADER_STRUCT.pack(
                    _STX2, len(payload), self._incompat, 0, seq, self.sysid, self.compid, msgid & 0xFFFF, msgid >> 16
                )
                + payload
            )
        extra = _EXTRA.get(msgid)
        if extra is None:
            extra = _EXTRA[msgid] = bytes((layout.crc_extra,))
        frame += _CRC.pack(crc16(extra, crc16(frame[1:])))
        if self.signer is not None:
            frame += self.signer.sign(frame)
        return frame


_EXTRA: dict[int, bytes] = {}  # msgid -> its CRC extra as the one byte the CRC takes last
