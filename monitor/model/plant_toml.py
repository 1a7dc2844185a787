"""The plant file's text from an identification: ``plant_toml`` (the whole file) and ``disturbance_table``.

Why apart from ``monitor.model.identification``: that module estimates (arrays in, a model out); this one
writes the plant file format (docs/reference/file-formats.md). They change for different reasons (a better
fit, or a new field of the file), and ``identify --air-only`` needs only the ``[disturbance]`` table, not the
estimator. Pure functions returning text: the caller (``monitor.pipelines.identify_log``) checks the text
loads as a plant and writes the file.
"""

from __future__ import annotations

import json
import math
import re
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from monitor.model.identification import Identification

__all__ = ["disturbance_table", "plant_toml"]


def _value(value: Any) -> str:
    """One TOML value on one line (matrices as ``[[a, b], [c, d]]``, inline tables for dicts)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, np.ndarray):
        return _value(value.tolist())
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }" if value else "{}"
    raise TypeError(f"cannot write {type(value).__name__} to a plant file")


def _key(name: str) -> str:
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else _value(name)


def _round(x: float, digits: int = 6) -> float:
    return float(f"{x:.{digits}g}") if math.isfinite(x) else x


def disturbance_table(gust: dict[str, float], turbulence: str | None, source: str | None = None) -> list[str]:
    """The ``[disturbance]`` table's lines for a gust measured by ``gust_from_residual``."""
    lines = [
        "[disturbance]",
        "# the gust input d (through D_cd) the flight met, as a first-order Gauss-Markov process: what",
        "# the model's one-step residual shows along D_cd (calm air: the model's own error)",
        f"sigma = {_value(_round(gust['sigma']))}   # deg",
        f"time_constant = {_value(_round(gust['time_constant']))}   # s (integral time scale)",
    ]
    if turbulence is not None:
        lines.append(f"turbulence = {_value(turbulence)}   # the level flown (sim-vehicle --turbulence)")
    if source is not None:
        lines.append(f"source = {_value(source)}")
    return lines


def plant_toml(
    result: Identification,
    *,
    name: str,
    description: str,
    tau_max: float,
    actuator_limit: float,
    tau_min: float = 0.0,
    turbulence: str | None = None,
    actuator_limit_source: str,
    signals: dict[str, Any],
    source_log: str,
    model: str,
    header: list[str] | None = None,
    condition: dict[str, float] | None = None,
    known_lags: dict[str, float] | None = None,
) -> str:
    """The plant file ``fault-monitor design`` / ``run`` take as it is (docs/reference/file-formats.md).

    ``signals`` is the ``[signals]`` table without ``operating_point`` (added here) and with ``measured`` and
    ``command`` sub-tables. ``D_cf = B_c`` (an elevator fault), ``D_cd`` = the alpha column of ``A_c`` (a
    vertical gust is an angle-of-attack disturbance, in degrees), ``C`` = identity of the states. ``condition``:
    the other measured signals' means where the model was identified (``[signals] condition``), if any. Inputs
    after the first (the elevator) are known inputs: their columns of ``B_c`` go to ``[known_inputs.linear]`` and
    their trims to ``condition`` (over the mean the caller measured), not to the plant's ``B_c``.
    """
    n = len(result.state_names)
    known = list(result.input_names[1:])
    B_c = result.B_c[:, :1]
    condition = dict(condition or {})
    condition.update({name: result.operating_point[name] for name in known})
    if "alpha" not in result.state_names:
        raise ValueError("the gust input D_cd needs alpha among the states")
    gust = result.A_c[:, [result.state_names.index("alpha")]]
    top: list[tuple[str, Any]] = [
        ("form", "continuous"),
        ("name", name),
        ("description", description),
        ("unit", "deg"),
        ("h", float(result.h)),
        ("tau_min", float(tau_min)),
        ("tau_max", float(tau_max)),
        ("A_c", result.A_c),
        ("B_c", B_c),
        ("D_cf", B_c),
        ("D_cd", gust),
        ("C", np.eye(n)),
    ]
    lines = [f"# {line}" for line in (header or [])]
    lines += [f"{key} = {_value(value)}" for key, value in top]
    lines += ["", "[actuator]", f"limit = {_value(float(actuator_limit))}   # deg, {actuator_limit_source}"]
    if result.disturbance is not None and result.disturbance["sigma"] > 0:
        lines += ["", *disturbance_table(result.disturbance, turbulence)]
    lines += ["", "[signals]"]
    plain = {key: v for key, v in signals.items() if not isinstance(v, dict)}
    for key, value in plain.items():
        lines.append(f"{key} = {_value(value)}")
    op = {s: _round(result.operating_point[s], 7) for s in (*result.state_names, *result.input_names[:1])}
    lines.append(f"operating_point = {_value(op)}")
    if condition:
        lines.append(f"condition = {_value({s: _round(v, 7) for s, v in condition.items()})}")
    for table in ("measured", "command"):
        if table in signals:
            lines.append(f"[signals.{table}]")
            lines += [f"{_key(key)} = {_value(value)}" for key, value in signals[table].items()]
    ident = {
        "source_log": source_log,
        "model": model,
        "states": list(result.state_names),
        "samples": result.samples,
        "samples_estimation": result.samples_estimation,
        "samples_validation": result.samples_validation,
        "validation_span_s": [_round(v) for v in result.validation_span_s],
        "operating_point_source": result.operating_point_source,
        "method": (
            "equation-error least squares, refined by output error"
            if result.method.get("refined")
            else "equation-error least squares"
        ),
        "excitation_s": [_round(result.excitation["start_s"]), _round(result.excitation["end_s"])],
        "fit_percent": {s: _round(f, 4) for s, f in result.fit_validation.items()},
    }
    lines += ["", "[identification]", "# information only: plant.py accepts this table and ignores it"]
    lines += [f"{key} = {_value(value)}" for key, value in ident.items()]
    for mode in result.modes:
        entry = {"name": mode.name, "wn_rad_s": _round(mode.wn), "zeta": _round(mode.zeta)}
        if mode.period_s is not None:
            entry["period_s"] = _round(mode.period_s)
        if not all(math.isfinite(v) for v in (mode.wn, mode.zeta)):
            entry = {"name": mode.name, "eigenvalues": [_round(e.real) for e in mode.eigenvalues]}
        lines += ["[[identification.modes]]", *(f"{key} = {_value(value)}" for key, value in entry.items())]
    if known:
        lines += [
            "",
            "[known_inputs.linear]",
            "# identified with the elevator: each one's column of B_c (state units per its unit), acting on its",
            "# deviation from its trim in [signals] condition; the estimator adds it to its prediction (not a fault)",
        ]
        lines += [
            f"{_key(name)} = {_value([_round(float(v)) for v in result.B_c[:, 1 + i]])}" for i, name in enumerate(known)
        ]
        if known_lags:
            lines += [
                "",
                "[known_inputs.lag]",
                "# each one's first-order lag (s) before its column acts, picked by the held-out fit (an engine's",
                "# thrust follows the lever in about a second)",
            ]
            lines += [f"{_key(name)} = {_value(float(known_lags[name]))}" for name in known if name in known_lags]
    return "\n".join(lines) + "\n"
