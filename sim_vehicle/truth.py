"""Where the ground truth goes: Zenoh ``<prefix>/<sysid>/truth`` (JSON) and optionally a JSON-lines file.

Why publish sample k at ``(k+1) h``: only then is ``tau(k)`` settled (applied, late or lost), so every
truth message is final and an evaluator never has to patch an earlier one. Publishing uses congestion
control BLOCK (a dropped truth sample would silently bias a score), and a failing put costs a log line,
never the simulation.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import IO

from monitor.errors import UserError

__all__ = ["TruthPublisher"]

log = logging.getLogger(__name__)


class TruthPublisher:
    """Publishes truth payloads to any of: a Zenoh session, a JSON-lines file."""

    def __init__(self, session=None, key: str | None = None, jsonl: str | Path | None = None) -> None:
        self.session = session
        self.key = key
        self.publisher = None
        self.published = 0
        self.errors = 0
        self._file: IO[str] | None = None
        if session is not None and key is not None:
            import zenoh

            self.publisher = session.declare_publisher(
                key, encoding=zenoh.Encoding.APPLICATION_JSON, congestion_control=zenoh.CongestionControl.BLOCK
            )
        if jsonl is not None:
            try:
                self._file = open(jsonl, "w", encoding="utf-8")
            except OSError as exc:
                raise UserError(f"--truth-jsonl {jsonl}: cannot write: {exc.strerror}") from None

    def publish(self, payload: dict) -> None:
        text = json.dumps(payload)
        if self.publisher is not None:
            try:
                self.publisher.put(text)
                self.published += 1
            except Exception as exc:  # a Zenoh hiccup must not stop the vehicle
                self.errors += 1
                log.warning("truth publication failed: %s", exc)
        if self._file is not None:
            self._file.write(text + "\n")
            self._file.flush()

    def close(self) -> None:
        """Close the file; the publisher is undeclared by the session owner (``close_quietly``)."""
        if self._file is not None:
            self._file.close()
            self._file = None
