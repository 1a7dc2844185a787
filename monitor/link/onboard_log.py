"""An autopilot's own flight log, told apart by its content: ArduPilot's DataFlash or PX4's ULog (else a tlog).

Why by content: logs get renamed (``log_12.bin``, ``flight.ulg``, ``00000042.log``...) and a user passes
whatever the ground station downloaded. Both kinds answer the same interface (``layouts``, ``counts``,
``records``, ``inventory``, ``close``), so ``analyse`` and ``identify`` read them the same way.
"""

from __future__ import annotations

from pathlib import Path

from monitor.link.dataflash import DataFlashLog, dataflash_kind, open_dataflash
from monitor.link.ulog import ULogLog, is_ulog, open_ulog

__all__ = ["open_onboard_log"]


def open_onboard_log(path: str | Path) -> DataFlashLog | ULogLog | None:
    """The opened on-board log ``path`` is (ULog or DataFlash), or None when it is neither (a tlog)."""
    if is_ulog(path):
        return open_ulog(path)
    if dataflash_kind(path):
        return open_dataflash(path)
    return None
