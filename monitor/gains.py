"""Gains files: what ``design`` writes and ``verify``, ``run`` and ``demo`` read (TOML).

A gains file records the method, the five gain matrices, the bounds the design claims, how its LMI was
solved (the path that produced the accepted point, the solver's status word there, the margin of the numpy
re-check) and the times, the certificate (Lyapunov matrices and polytope vertices) and the hash of the plant
it was designed for, so that ``verify`` can re-check the certificate and ``run`` can refuse a mismatch.

An envelope gains file (``design --plant ENVELOPE.toml``, docs/explanation/envelope.md) holds one such set per
operating point, ``[point.<name>]`` with the keys of ``[gains]`` (its solver, notes and certificate as sub-tables),
the schedule, and the ``[common_certificate]`` over every point; :func:`read_gains` refuses it with a line that
says so, and a single-point gains file stays what it was.
"""

from __future__ import annotations

import json
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.files import write_text_atomically
from monitor.model.closed_loop import Gains
from monitor.model.plant import Plant

if TYPE_CHECKING:  # the envelope design imports cvxpy: not for every reader of a gains file
    from monitor.design.envelope import EnvelopeDesign
    from monitor.model.envelope import Envelope

__all__ = [
    "GainsFile",
    "write_gains",
    "read_gains",
    "parse_gain_matrix",
    "EnvelopeGainsFile",
    "CommonRecord",
    "write_envelope_gains",
    "read_envelope_gains",
    "is_envelope_gains",
]

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
    write_text_atomically(path, _to_toml(_gains_doc(result, plant)))


def _gains_doc(result: DesignResult, plant: Plant) -> dict[str, dict[str, Any]]:
    """The tables of a single-point gains file: ``gains``, ``solver``, ``notes`` and ``certificate``."""
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
    return doc


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
    if isinstance(value, dict):  # an inline table (an envelope point's place: { airspeed = 51.4 })
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to a gains file")


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def _to_toml(doc: dict[str, dict[str, Any]]) -> str:
    lines: list[str] = []
    for table, entries in doc.items():
        lines.append(f"[{table}]")
        lines.extend(f"{key} = {_toml_value(value)}" for key, value in entries.items())
        lines.append("")
    return "\n".join(lines)


def _load_toml(path: str | Path) -> dict[str, Any]:
    source = str(path)
    try:
        return tomllib.loads(Path(path).read_text("utf-8"))
    except FileNotFoundError:
        raise UserError(f"{source}: gains file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{source}: cannot read gains file: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{source}: not valid TOML: {exc}") from None


def read_gains(path: str | Path) -> GainsFile:
    """Parse and validate a gains file; every problem is a one-line UserError naming the key and file."""
    source = str(path)
    raw = _load_toml(path)
    if "envelope" in raw:
        raise UserError(
            f"{source}: is an envelope gains file (per-point gains and a common certificate, written by "
            "`fault-monitor design --plant ENVELOPE.toml`): verify takes it with its envelope plant file; this "
            "command takes single-point gains"
        )
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise UserError(f"{source}: unknown table '{unknown[0]}' (allowed: {', '.join(sorted(_TOP_KEYS))})")
    return _gains_file(raw, "", source, source)


def _gains_file(raw: dict[str, Any], prefix: str, source: str, label: str) -> GainsFile:
    """One set of gains from its tables: ``gains`` (required), ``solver``, ``certificate``; keys named
    ``<prefix>gains.L`` etc. in errors (an envelope's point: ``point.<name>.`` with ``gains`` its own table)."""
    here = prefix.rstrip(".") if prefix else "gains"
    table = raw.get("gains") if not prefix else raw
    if not isinstance(table, dict):
        raise UserError(f"{source}: missing [{here}] table")
    extra = {"solver", "certificate", "notes"} if prefix else set()
    unknown = sorted(set(table) - _GAINS_KEYS - extra)
    if unknown:
        raise UserError(f"{source}: unknown key '{here}.{unknown[0]}'")
    mats = {}
    for name in GAIN_NAMES:
        if name not in table:
            raise UserError(f"{source}: key '{here}.{name}' is missing")
        mats[name] = _matrix(table[name], f"{source}: key '{here}.{name}'")
    meta = {k: v for k, v in table.items() if k not in GAIN_NAMES and k not in extra}
    holder = table if prefix else raw
    solver = holder.get("solver", {})
    if not isinstance(solver, dict):
        raise UserError(f"{source}: '{prefix}solver' must be a table")
    meta["solver"] = solver
    certificate = holder.get("certificate") or {}
    if not isinstance(certificate, dict):
        raise UserError(f"{source}: '{prefix}certificate' must be a table")
    cert = {}
    for k, v in certificate.items():
        cert[k] = _matrix(v, f"{source}: key '{prefix}certificate.{k}'")
    return GainsFile(Gains(**mats), meta, cert, label)


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


# -- envelope gains files: per-point gains and one certificate over the envelope ---------------------------------

_ENVELOPE_TOP = {"envelope", "point", "common_certificate", "notes"}
_ENVELOPE_KEYS = {
    "name",
    "plant",
    "plant_hash",
    "schedule",
    "points",
    "at",
    "method",
    "jobs",
    "points_seconds",
    "certificate_seconds",
    "total_seconds",
}
_COMMON_KEYS = {
    "P",
    "gamma",
    "vertices",
    "verdicts",
    "statement",
    "not_covered",
    "redesigned",
    "path",
    "status",
    "check_margin",
    "seconds",
}


@dataclass
class CommonRecord:
    """The envelope's common certificate as the file records it: ``P``, ``gamma`` and each point's vertices."""

    P: np.ndarray
    gamma: float
    vertices: dict[str, np.ndarray]
    meta: dict[str, Any]


class EnvelopeGainsFile:
    """A parsed envelope gains file: each point's gains (a :class:`GainsFile` each), where the points sit in the
    schedule, the common certificate and the design's per-point verdicts."""

    def __init__(
        self,
        source: str,
        meta: dict[str, Any],
        points: dict[str, GainsFile],
        at: dict[str, dict[str, float]],
        common: CommonRecord | None,
        verdicts: dict[str, dict[str, Any]],
    ) -> None:
        self.source = source
        self.meta = meta
        self.points = points
        self.at = at
        self.common = common
        self.verdicts = verdicts

    @property
    def schedule(self) -> tuple[str, ...]:
        return tuple(self.meta.get("schedule", ()))

    def gains(self) -> dict[str, Gains]:
        return {name: gf.gains for name, gf in self.points.items()}

    def check_envelope(self, envelope: Envelope) -> str | None:
        """Refuse gains whose points or shapes do not fit the envelope; return a warning when a hash differs."""
        if list(self.points) != list(envelope.names):
            raise UserError(
                f"{self.source}: has gains for points {', '.join(self.points)}; the envelope {envelope.source} has "
                f"points {', '.join(envelope.names)}"
            )
        for point in envelope.points:
            self.points[point.name].check_plant(point.plant)
        if self.meta.get("plant_hash") not in (None, envelope.digest):
            return (
                f"gains were designed for another envelope ({self.meta.get('plant')}); checking them on "
                f"{envelope.source}"
            )
        return None


def write_envelope_gains(path: str | Path, design: EnvelopeDesign) -> None:
    """The envelope's gains file: ``[envelope]``, then ``[point.<name>]`` (the keys of a single-point ``[gains]``
    table, with that file's other tables as ``[point.<name>.solver]``, ``.notes`` and ``.certificate``), the
    ``[common_certificate]`` (P, gamma, each point's vertices and verdict) and the ``[notes]``. Atomically."""
    env = design.envelope
    names = list(env.names)
    doc: dict[str, dict[str, Any]] = {
        "envelope": {
            "name": env.name,
            "plant": env.source,
            "plant_hash": env.digest,
            "schedule": list(env.schedule),
            "points": names,
            "at": [dict(env.point(n).at) for n in names],
            "method": design.method,
            "jobs": design.jobs,
            "points_seconds": round(design.points_seconds, 4),
            "certificate_seconds": round(design.certificate_seconds, 4),
            "total_seconds": round(design.total_seconds, 4),
        }
    }
    for name in names:
        tables = _gains_doc(design.results[name], env.point(name).plant)
        doc[f"point.{name}"] = tables["gains"]
        for table in ("solver", "notes", "certificate"):
            if table in tables:
                doc[f"point.{name}.{table}"] = tables[table]
    common = design.common
    doc["common_certificate"] = {
        "statement": _statement(),
        "not_covered": _not_covered(),
        "P": _rows(common.P),
        "gamma": float(common.gamma),
        "redesigned": list(design.redesigned),
        "path": common.solved.path,
        "status": common.solved.status,
        "check_margin": float(common.solved.margin),
        "seconds": round(common.seconds, 4),
    }
    doc["common_certificate.vertices"] = {name: _rows(common.vertices[name]) for name in names}
    for name in names:
        result = design.results[name]
        doc[f"common_certificate.verdicts.{name}"] = {
            "gamma_e": float(result.gamma_e),
            "gamma_z": float(result.gamma_z),
            "own_certificate": bool(result.certificate),
            "observer": "re-designed for the common P" if name in design.redesigned else "the point's own design",
            "in_common_certificate": True,
        }
    doc["notes"] = {"lines": list(design.notes)}
    write_text_atomically(path, _to_toml(doc))


def _statement() -> str:
    from monitor.design.envelope import STATEMENT

    return STATEMENT


def _not_covered() -> str:
    from monitor.design.envelope import NOT_COVERED

    return NOT_COVERED


def is_envelope_gains(path: str | Path) -> bool:
    """True when ``path`` is a readable TOML file with an ``[envelope]`` table."""
    try:
        return "envelope" in tomllib.loads(Path(path).read_text("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False


def read_envelope_gains(path: str | Path) -> EnvelopeGainsFile:
    """Parse and validate an envelope gains file; every problem is one line naming the key and the file."""
    source = str(path)
    raw = _load_toml(path)
    if "envelope" not in raw:
        raise UserError(
            f"{source}: is a single-point gains file (no [envelope] table); an envelope plant needs the gains "
            "file `fault-monitor design --plant ENVELOPE.toml` writes"
        )
    unknown = sorted(set(raw) - _ENVELOPE_TOP)
    if unknown:
        raise UserError(f"{source}: unknown table '{unknown[0]}' (allowed: {', '.join(sorted(_ENVELOPE_TOP))})")
    env = raw["envelope"]
    if not isinstance(env, dict):
        raise UserError(f"{source}: [envelope] must be a table")
    bad = sorted(set(env) - _ENVELOPE_KEYS)
    if bad:
        raise UserError(f"{source}: unknown key 'envelope.{bad[0]}'")
    names = env.get("points")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise UserError(f"{source}: key 'envelope.points' must be the list of the points' names")
    schedule = env.get("schedule")
    if not isinstance(schedule, list) or not all(isinstance(s, str) for s in schedule):
        raise UserError(f"{source}: key 'envelope.schedule' must be a list of signal names")
    places = env.get("at")
    if not isinstance(places, list) or len(places) != len(names) or not all(isinstance(a, dict) for a in places):
        raise UserError(f"{source}: key 'envelope.at' must hold one table of schedule values per point")
    tables = raw.get("point")
    if not isinstance(tables, dict):
        raise UserError(f"{source}: missing [point.<name>] tables")
    for name in tables:
        if name not in names:
            raise UserError(f"{source}: table [point.{name}] is not a point of envelope.points ({', '.join(names)})")
    points = {}
    for name in names:
        table = tables.get(name)
        if not isinstance(table, dict):
            raise UserError(f"{source}: missing [point.{name}] table")
        points[name] = _gains_file(table, f"point.{name}.", source, f"{source} [point.{name}]")
    at = {name: {str(k): float(v) for k, v in place.items()} for name, place in zip(names, places, strict=True)}
    common, verdicts = _common(raw.get("common_certificate"), names, source)
    meta = dict(env)
    meta["notes"] = (raw.get("notes") or {}).get("lines", [])
    return EnvelopeGainsFile(source, meta, points, at, common, verdicts)


def _common(table: Any, names: list[str], source: str) -> tuple[CommonRecord | None, dict[str, dict[str, Any]]]:
    if table is None:
        return None, {}
    if not isinstance(table, dict):
        raise UserError(f"{source}: [common_certificate] must be a table")
    bad = sorted(set(table) - _COMMON_KEYS)
    if bad:
        raise UserError(f"{source}: unknown key 'common_certificate.{bad[0]}'")
    for key in ("P", "gamma"):
        if key not in table:
            raise UserError(f"{source}: key 'common_certificate.{key}' is missing")
    P = _matrix(table["P"], f"{source}: key 'common_certificate.P'")
    gamma = table["gamma"]
    if isinstance(gamma, bool) or not isinstance(gamma, (int, float)):
        raise UserError(f"{source}: key 'common_certificate.gamma' must be a number, got {gamma!r}")
    listed = table.get("vertices") or {}
    if not isinstance(listed, dict):
        raise UserError(f"{source}: [common_certificate.vertices] must be a table of one matrix per point")
    vertices = {}
    for name, value in listed.items():
        if name not in names:
            raise UserError(f"{source}: key 'common_certificate.vertices.{name}' names no point of the envelope")
        vertices[name] = _matrix(value, f"{source}: key 'common_certificate.vertices.{name}'")
    verdicts = table.get("verdicts") or {}
    if not isinstance(verdicts, dict) or not all(isinstance(v, dict) for v in verdicts.values()):
        raise UserError(f"{source}: [common_certificate.verdicts.<name>] must be tables")
    meta = {k: v for k, v in table.items() if k not in ("P", "gamma", "vertices", "verdicts")}
    return CommonRecord(P=P, gamma=float(gamma), vertices=vertices, meta=meta), dict(verdicts)
