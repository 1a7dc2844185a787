"""Gains files: what ``design`` writes and ``verify``, ``run`` and ``demo`` read (TOML).

A gains file records the method, the five gain matrices, the bounds the design claims, how its LMI was
solved (the path that produced the accepted point, the solver's status word there, the margin of the numpy
re-check) and the times, the certificate (Lyapunov matrices and polytope vertices) and the hash of the plant
it was designed for, so that ``verify`` can re-check the certificate and ``run`` can refuse a mismatch.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.files import write_text_atomically
from monitor.model.closed_loop import Gains
from monitor.model.plant import Plant

__all__ = ["GainsFile", "write_gains", "read_gains", "parse_gain_matrix"]

GAIN_NAMES = ("L", "M", "K1", "K2", "K3")
_GAINS_KEYS = set(GAIN_NAMES) | {
    "method",
    "objective",
    "max_losses",
    "gamma_e",
    "gamma_z",
    "plant_hash",
    "plant",
    "bounds_apply_to",
    "fault_time_constant",
}
_TOP_KEYS = {"gains", "solver", "certificate", "notes"}


class GainsFile:
    """A parsed gains file: the gains plus whatever else it recorded."""

    def __init__(self, gains: Gains, meta: dict[str, Any], certificate: dict[str, np.ndarray], source: str) -> None:
        self.gains = gains
        self.meta = meta
        self.certificate = certificate
        self.source = source

    @property
    def method(self) -> str:
        return str(self.meta.get("method", "unknown"))

    @property
    def fault_time_constant(self) -> float | None:
        """Seconds of the low-pass on the reported f_hat (``monitor.model.estimator``); None: reported as estimated."""
        value = self.meta.get("fault_time_constant")
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise UserError(
                f"{self.source}: key 'gains.fault_time_constant' must be a positive number of seconds, got {value!r}"
            )
        return float(value)

    def check_plant(self, plant: Plant) -> None:
        """Refuse gains whose shapes do not fit; a hash mismatch is the caller's to report."""
        try:
            self.gains.check_shapes(plant)
        except ValueError as exc:
            raise UserError(f"{self.source}: {exc}") from None


def _rows(a: np.ndarray) -> list[list[float]]:
    return [[float(x) for x in row] for row in np.atleast_2d(a)]


def write_gains(path: str | Path, result: DesignResult, plant: Plant) -> None:
    """Write atomically (temp file + rename) so a failed run never leaves a half-written gains file."""
    g = result.gains
    doc: dict[str, Any] = {
        "gains": {
            "method": result.method,
            **{name: _rows(getattr(g, name)) for name in GAIN_NAMES},
            "gamma_e": float(result.gamma_e),
            "gamma_z": float(result.gamma_z),
            "bounds_apply_to": result.bounds_apply_to,
            "plant": plant.source,
            "plant_hash": plant.digest,
            **({"objective": result.objective} if result.objective else {}),
            **({"max_losses": result.max_losses} if result.max_losses else {}),
            **({"fault_time_constant": float(result.fault_time_constant)} if result.fault_time_constant else {}),
        },
        "solver": {
            **(
                {
                    "path": result.solved.path,
                    "status": result.solved.status,
                    "check_margin": float(result.solved.margin),
                }
                if result.solved
                else {"path": "none"}
            ),
            "build_seconds": round(result.build_seconds, 4),
            "solve_seconds": round(result.solve_seconds, 4),
            "total_seconds": round(result.total_seconds, 4),
        },
        "notes": {"lines": list(result.notes)},
    }
    if result.certificate:
        doc["certificate"] = {k: _rows(v) for k, v in result.certificate.items()}
    write_text_atomically(path, _to_toml(doc))


def _toml_value(value: Any) -> str:
    """One TOML value on one line: matrices stay readable as ``[[1.87], [1.63]]``, as in CONTRACT.md.

    Why not a TOML library: tomli-w writes every nested array over several lines; our values are only
    strings, numbers and (nested) lists of them, and JSON's string escapes are valid TOML escapes.
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)  # Python's float repr (incl. inf, nan) is valid TOML
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to a gains file")


def _to_toml(doc: dict[str, dict[str, Any]]) -> str:
    lines: list[str] = []
    for table, entries in doc.items():
        lines.append(f"[{table}]")
        lines.extend(f"{key} = {_toml_value(value)}" for key, value in entries.items())
        lines.append("")
    return "\n".join(lines)


def read_gains(path: str | Path) -> GainsFile:
    """Parse and validate a gains file; every problem is a one-line UserError naming the key and file."""
    source = str(path)
    try:
        raw = tomllib.loads(Path(path).read_text("utf-8"))
    except FileNotFoundError:
        raise UserError(f"{source}: gains file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{source}: cannot read gains file: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{source}: not valid TOML: {exc}") from None
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise UserError(f"{source}: unknown table '{unknown[0]}' (allowed: {', '.join(sorted(_TOP_KEYS))})")
    table = raw.get("gains")
    if not isinstance(table, dict):
        raise UserError(f"{source}: missing [gains] table")
    unknown = sorted(set(table) - _GAINS_KEYS)
    if unknown:
        raise UserError(f"{source}: unknown key 'gains.{unknown[0]}'")
    mats = {}
    for name in GAIN_NAMES:
        if name not in table:
            raise UserError(f"{source}: key 'gains.{name}' is missing")
        mats[name] = _matrix(table[name], f"{source}: key 'gains.{name}'")
    meta = {k: v for k, v in table.items() if k not in GAIN_NAMES}
    meta["solver"] = raw.get("solver", {})
    cert = {}
    for k, v in (raw.get("certificate") or {}).items():
        cert[k] = _matrix(v, f"{source}: key 'certificate.{k}'")
    return GainsFile(Gains(**mats), meta, cert, source)


def _matrix(value: Any, where: str) -> np.ndarray:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [[value]]
    if not isinstance(value, list) or not value or not all(isinstance(r, list) and r for r in value):
        raise UserError(f"{where} must be a matrix written as a list of rows, e.g. [[1.87], [1.63]]")
    if len({len(r) for r in value}) != 1:
        raise UserError(f"{where} has rows of different lengths")
    if any(isinstance(x, bool) or not isinstance(x, (int, float)) for r in value for x in r):
        raise UserError(f"{where} must contain only numbers")
    arr = np.array(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise UserError(f"{where} contains a non-finite number")
    return arr


def parse_gain_matrix(text: str, name: str) -> np.ndarray:
    """A gain given on the command line: ``1.87,1.63`` is a column; ``a,b;c,d`` separates rows."""
    try:
        if ";" in text:
            rows = [[float(x) for x in row.split(",")] for row in text.split(";")]
        else:
            rows = [[float(x)] for x in text.split(",")]
    except ValueError:
        raise UserError(f"--{name} '{text}': expected numbers like 1.87,1.63 (column) or 1,2;3,4 (rows)") from None
    return _matrix(rows, f"--{name}")
