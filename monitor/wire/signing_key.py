"""The MAVLink 2 signing-key file both ends read (one format for the vehicle and the monitor)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from monitor.errors import UserError

__all__ = ["load_signing_key"]


def load_signing_key(path: str | Path) -> bytes:
    """Read a MAVLink 2 signing key: 32 raw bytes, 64 hex digits, or a passphrase (SHA-256 of it).

    A passphrase is hashed like MAVProxy's ``signing setup PASSPHRASE``, so the same text works there.
    """
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise UserError(f"--signing-key {path}: cannot read: {exc.strerror}") from None
    if len(raw) == 32:
        return raw
    try:
        text = raw.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise UserError(f"--signing-key {path}: expected 32 raw bytes, 64 hex digits or a text passphrase") from None
    if not text:
        raise UserError(f"--signing-key {path}: the file is empty")
    if len(text) == 64:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    return hashlib.sha256(text.encode("utf-8")).digest()
