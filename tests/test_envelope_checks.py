"""`threshold` and `detectability` on an envelope plant: every point's figure, as the single-point command gives it
on that point's own plant and gains files, and the worst point last.

The envelope is the committed pair ``tests/data/c172p-envelope-90-100kt*.toml`` (a plant and its gains, designed
by ``fault-monitor design``). Its [disturbance] tables do not say which turbulence they were measured in; a copy
that says "light" (and the gains' hashes moved to it) is what --turbulence scales. The independent path cuts each
point's ``[point.plant]`` and ``[point.<name>]`` tables out of the files as text, into a single-point plant and
gains file each.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from monitor.cli import main
from monitor.model.envelope import load_envelope
from tests.computed_once import computed_once

DATA = Path(__file__).parent / "data"
PLANT = DATA / "c172p-envelope-90-100kt.toml"
GAINS = DATA / "c172p-envelope-90-100kt-gains.toml"
NAMES = ["c172p-90kt", "c172p-100kt"]


def point_plant_text(text: str, name: str) -> str:
    """The ``[point.plant]`` tables of point ``name`` as a single-point plant file."""
    blocks = re.split(r"^\[\[point\]\]\n", text, flags=re.M)[1:]
    block = next(b for b in blocks if re.search(rf'^name = "{re.escape(name)}"$', b, flags=re.M))
    body = block[block.index("[point.plant]\n") + len("[point.plant]\n") :]
    return re.sub(r"^(\[\[?)point\.plant\.", r"\1", body, flags=re.M)


def point_gains_text(text: str, name: str) -> str:
    """The ``[point.<name>]`` tables of an envelope gains file as a single-point gains file."""
    head = f"[point.{name}]\n"
    rest = text[text.index(head) + len(head) :]
    end = re.search(rf"^\[(?!point\.{re.escape(name)}\.)", rest, flags=re.M)
    body = rest[: end.start()] if end else rest
    return "[gains]\n" + re.sub(rf"^\[point\.{re.escape(name)}\.", "[", body, flags=re.M)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """The envelope pair (its disturbance measured in light turbulence) and each point's own plant and gains."""
    tmp = tmp_path_factory.mktemp("envelope-checks")
    before = load_envelope(PLANT)
    plant_text = PLANT.read_text().replace(
        "[point.plant.disturbance]\n", '[point.plant.disturbance]\nturbulence = "light"\n'
    )
    (tmp / "env.toml").write_text(plant_text)
    after = load_envelope(tmp / "env.toml")
    gains_text = GAINS.read_text().replace(before.digest, after.digest)
    for name in NAMES:
        gains_text = gains_text.replace(before.point(name).plant.digest, after.point(name).plant.digest)
    (tmp / "env-gains.toml").write_text(gains_text)
    out = {"plant": tmp / "env.toml", "gains": tmp / "env-gains.toml"}
    for name in NAMES:
        (tmp / f"{name}.toml").write_text(point_plant_text(plant_text, name))
        (tmp / f"{name}-gains.toml").write_text(point_gains_text(gains_text, name))
        out[name], out[f"{name}-gains"] = tmp / f"{name}.toml", tmp / f"{name}-gains.toml"
    return out


def _json(capsys, *argv: str) -> dict:
    capsys.readouterr()
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def _check_envelope_answer(env: dict, singles: dict[str, dict], figure: str) -> None:
    assert set(env) == {"points", "worst"}
    assert [p["name"] for p in env["points"]] == NAMES
    for point in env["points"]:
        single = singles[point["name"]]
        assert set(point) == {"name", *single}  # today's keys, and the point's name
        assert point[figure] == pytest.approx(single[figure], rel=1e-9)
        assert point["threshold"] == pytest.approx(single["threshold"], rel=1e-9)
    worst = max(env["points"], key=lambda p: p[figure])
    assert env["worst"] == worst
    assert worst[figure] == max(s[figure] for s in singles.values())


def test_threshold_bounds_every_point_as_the_single_point_command_does(files, capsys, monkeypatch) -> None:
    import monitor.checks.threshold

    # the envelope's text answer prints the bounds its JSON answer computed (tests/computed_once.py): 9 s
    bounds = computed_once(monkeypatch, monitor.checks.threshold, "fault_threshold")
    D = ["--disturbance-bound", "0.001"]
    singles = {
        n: _json(capsys, "threshold", "--plant", str(files[n]), "--gains", str(files[f"{n}-gains"]), *D, "--json")
        for n in NAMES
    }
    assert len({s["threshold"] for s in singles.values()}) == 2  # the points differ: the max means something
    env_args = ["threshold", "--plant", str(PLANT), "--gains", str(GAINS), *D]
    env = _json(capsys, *env_args, "--json")
    _check_envelope_answer(env, singles, "threshold")

    assert main(env_args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3
    for line, name in zip(lines[:-1], NAMES, strict=True):
        assert line.startswith(f"point {name}: threshold {singles[name]['threshold']:.6g} deg")
    worst = env["worst"]
    assert lines[-1] == f"envelope: worst point {worst['name']}: threshold {worst['threshold']:.6g} deg"
    assert len(bounds) == 4  # two single-point files, two points of the envelope: each computed for real


def test_detectability_predicts_every_point_as_the_single_point_command_does(files, capsys) -> None:
    air = ["--turbulence", "moderate"]
    singles = {
        n: _json(capsys, "detectability", "--plant", str(files[n]), "--gains", str(files[f"{n}-gains"]), *air, "--json")
        for n in NAMES
    }
    assert len({s["bias"] for s in singles.values()}) == 2
    env_args = ["detectability", "--plant", str(files["plant"]), "--gains", str(files["gains"]), *air]
    env = _json(capsys, *env_args, "--json")
    _check_envelope_answer(env, singles, "bias")

    assert main(env_args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3
    for line, name in zip(lines[:-1], NAMES, strict=True):
        assert line.startswith(f"point {name}: a bias of {singles[name]['bias']:.4g} deg or more detected")
    worst = env["worst"]
    assert lines[-1].startswith(f"envelope: worst point {worst['name']}: smallest detectable bias {worst['bias']:.4g}")


def test_monte_carlo_with_an_envelope_is_one_line_refused(files, capsys) -> None:
    argv = ["detectability", "--plant", str(files["plant"]), "--gains", str(files["gains"]), "--turbulence", "light"]
    capsys.readouterr()
    assert main([*argv, "--monte-carlo", "2", "--aircraft", "c172p"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1
    assert "--monte-carlo" in captured.err and "envelope" in captured.err


def test_a_point_that_fails_is_the_one_line_error_naming_it(capsys) -> None:
    # the committed envelope's [disturbance] tables do not say which turbulence they were measured in
    capsys.readouterr()
    argv = ["detectability", "--plant", str(PLANT), "--gains", str(GAINS), "--turbulence", "light"]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1
    assert "point 'c172p-90kt'" in captured.err and "turbulence" in captured.err
