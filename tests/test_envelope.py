"""Envelope plants: the file's one-line errors, assemble -> design -> verify over three airspeeds, verify refusing
per-point-stable gains without a common Lyapunov matrix, and single-point files unchanged."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.errors import UserError
from monitor.model.envelope import is_envelope, load_envelope, parse_envelope
from monitor.model.plant import load_plant, parse_plant
from tests.computed_once import computed_once
from tests.envelope_files import A1, A2, documented_envelope, no_common_p_pair, pair_plant_table, plant_text

ROOT = Path(__file__).resolve().parents[1]
AIRSPEEDS = (40.0, 51.4, 62.0)


def _indent_plant(text: str) -> str:
    """A single-point plant file as the ``[point.plant]`` of an envelope (its tables moved under it)."""
    return re.sub(r"^\[(\[?)", r"[\1point.plant.", text, flags=re.M)


def envelope_text(*points: tuple[str, float, str], schedule: str = '["airspeed"]', extra: str = "") -> str:
    """An envelope of ``(name, airspeed, single-point plant text)`` points."""
    body = f'form = "envelope"\nname = "test"\nschedule = {schedule}\n{extra}'
    for name, V, text in points:
        body += f'\n[[point]]\nname = "{name}"\nat = {{ airspeed = {V} }}\n[point.plant]\n{_indent_plant(text)}'
    return body


def _three() -> list[tuple[str, float, str]]:
    return [(f"v{int(V)}", V, plant_text(V)) for V in AIRSPEEDS]


def test_an_envelope_parses_and_its_points_keep_their_own_plant_hash() -> None:
    env = parse_envelope(envelope_text(*_three()), "env.toml")
    assert env.names == ("v40", "v51", "v62") and env.schedule == ("airspeed",)
    assert env.at_matrix.ravel().tolist() == list(AIRSPEEDS)
    for point, V in zip(env.points, AIRSPEEDS, strict=True):
        assert point.plant.digest == parse_plant(plant_text(V), "x").digest  # gains for the file fit the point
        assert point.plant.signals["operating_point"]["airspeed"] == V
    assert env.nearest({"airspeed": 45.0}).name == "v40" and env.nearest({"airspeed": 58.0}).name == "v62"
    # the dynamics differ across the envelope, as dynamic pressure says: M_alpha ~ V^2
    m_alpha = [p.plant.continuous.A_c[1, 0] for p in env.points]
    assert m_alpha[2] / m_alpha[0] == pytest.approx((62.0 / 40.0) ** 2)


def _bad_cases() -> list[tuple[str, str, str]]:
    a, b = plant_text(40.0), plant_text(60.0)
    two_state = plant_text(60.0).replace('outputs = ["alpha", "q", "theta", "airspeed"]', 'outputs = ["alpha", "q"]')
    return [
        ("unknown top key", envelope_text(("a", 40, a), ("b", 60, b), extra="colour = 1\n"), "unknown key 'colour'"),
        ("one point", envelope_text(("a", 40, a)), "at least 2 points, got 1"),
        (
            "unknown point key",
            envelope_text(("a", 40, a), ("b", 60, b)).replace('name = "b"', 'name = "b"\nweight = 2', 1),
            "point 'b': unknown key 'weight'",
        ),
        (
            "at outside the schedule",
            envelope_text(("a", 40, a), ("b", 60, b)).replace("at = { airspeed = 60 }", "at = { bank = 30 }"),
            "'at' names 'bank', which is not in the schedule (airspeed)",
        ),
        (
            "at misses a variable",
            envelope_text(("a", 40, a), ("b", 60, b), schedule='["airspeed", "alpha"]'),
            "point 'a': 'at' misses the schedule variable(s) 'alpha'",
        ),
        (
            "duplicate at",
            envelope_text(("a", 60, b), ("b", 60, b)),
            "points 'a' and 'b' are both at airspeed = 60",
        ),
        ("different h", envelope_text(("a", 40, a), ("b", 60, plant_text(60.0, h=0.02))), "h = 0.02 differs"),
        ("different signals", envelope_text(("a", 40, a), ("b", 60, two_state)), "outputs"),
        (
            "bad key in a point's plant",
            envelope_text(("a", 40, a), ("b", 60, b)).replace("h = 0.05", "hh = 0.05", 1),
            "point 'a': unknown key 'hh'",
        ),
        (
            "not measured",
            envelope_text(("a", 40, a), ("b", 60, b), schedule='["load_factor"]').replace(
                "{ airspeed", "{ load_factor"
            ),
            "schedule variable 'load_factor' is not a measured signal",
        ),
        ("three variables", envelope_text(("a", 40, a), ("b", 60, b), schedule='["a", "b", "c"]'), "at most 2"),
        ("duplicate names", envelope_text(("a", 40, a), ("a", 60, b)), "two points are named 'a'"),
        ("bad name", envelope_text(("a b", 40, a), ("c", 60, b)), "key 'name' must be a name"),
        (
            "at off the trim",
            envelope_text(("a", 45, a), ("b", 60, b)),
            "at airspeed = 45 but its [signals] operating_point has airspeed = 40",
        ),
    ]


@pytest.mark.parametrize("text, message", [c[1:] for c in _bad_cases()], ids=[c[0] for c in _bad_cases()])
def test_every_mistake_in_an_envelope_file_is_one_line_naming_it(text: str, message: str) -> None:
    with pytest.raises(UserError) as err:
        parse_envelope(text, "env.toml")
    assert message in str(err.value) and "\n" not in str(err.value) and str(err.value).startswith("env.toml")


def test_dimensions_must_match() -> None:
    two_states = pair_plant_table(A1).replace("h = 0.1", "h = 0.05").replace("tau_max = 0.0", "tau_max = 0.023")
    text = envelope_text(("a", 40, plant_text(40.0)))
    text += f'\n[[point]]\nname = "b"\nat = {{ airspeed = 60 }}\n[point.plant]\n{two_states}'
    with pytest.raises(UserError, match=r"env.toml: point 'b': has 2 states, point 'a' 4"):
        parse_envelope(text, "env.toml")


def test_single_point_loaders_and_envelope_loaders_tell_the_files_apart(tmp_path: Path) -> None:
    env_file = tmp_path / "env.toml"
    env_file.write_text(envelope_text(*_three()))
    single = tmp_path / "one.toml"
    single.write_text(plant_text(51.4))
    assert is_envelope(env_file) and not is_envelope(single) and not is_envelope("paper")
    with pytest.raises(UserError, match="is an envelope plant file") as err:
        load_plant(env_file)
    assert "\n" not in str(err.value)
    with pytest.raises(UserError, match='must be "envelope"'):
        load_envelope(single)
    assert load_plant(single).n == 4  # single-point files: unchanged


def test_envelope_command_assembles_points_sorted_by_the_schedule(tmp_path: Path, capsys) -> None:
    files = []
    for V in (62.0, 40.0, 51.4):  # out of order on purpose
        path = tmp_path / f"leg-{V:g}.toml"
        path.write_text(plant_text(V))
        files.append(str(path))
    out = tmp_path / "env.toml"
    assert main(["envelope", *files, "--schedule", "airspeed", "--out", str(out)]) == 0
    env = load_envelope(out)
    assert env.names == ("leg-40", "leg-51-4", "leg-62") and env.at_matrix.ravel().tolist() == [40.0, 51.4, 62.0]
    assert "3 points scheduled by airspeed" in capsys.readouterr().out
    # the schedule's signal must be in every point's operating point
    bare = tmp_path / "bare.toml"
    bare.write_text(plant_text(45.0, op=False))
    assert main(["envelope", files[0], str(bare), "--schedule", "airspeed", "--out", str(tmp_path / "x.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "bare.toml: has no [signals] operating_point" in err and len(err.splitlines()) == 1
    assert main(["envelope", *files, "--schedule", "bank", "--out", str(tmp_path / "x.toml")]) == 2
    assert "operating_point and condition have no 'bank'" in capsys.readouterr().err
    assert not (tmp_path / "x.toml").exists()


@pytest.mark.slow
def test_assemble_design_verify_round_trip_over_three_airspeeds(tmp_path: Path, capsys, monkeypatch) -> None:
    import monitor.checks.envelope

    files = []
    for V in AIRSPEEDS:
        path = tmp_path / f"c172p-{V:g}.toml"
        path.write_text(plant_text(V))
        files.append(str(path))
    env, gains = tmp_path / "env.toml", tmp_path / "gains.toml"

    def cli(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "monitor", *args], capture_output=True, text=True, timeout=300)

    assert cli("envelope", *files, "--schedule", "airspeed", "--out", str(env)).returncode == 0
    done = cli("design", "--plant", str(env), "--out", str(gains), "--jobs", "2")
    assert done.returncode == 0, done.stderr
    assert "on a local Dask cluster of 2 processes" in done.stderr and done.stderr.count("point '") >= 3  # progress
    assert "common     gamma" in done.stdout
    from monitor.gains import read_envelope_gains, read_gains

    gf = read_envelope_gains(gains)
    envelope = load_envelope(env)
    assert list(gf.points) == list(envelope.names) and gf.schedule == ("airspeed",)
    for point in envelope.points:  # per point: the single-point [gains] format, for the point's own plant
        assert gf.points[point.name].meta["plant_hash"] == point.plant.digest
        assert gf.points[point.name].certificate["P"].shape == (10, 10)
    assert gf.common is not None and gf.common.P.shape == (10, 10) and gf.common.gamma > 0
    with pytest.raises(UserError, match="is an envelope gains file"):
        read_gains(gains)
    # verify twice (the file as designed, then with the common bound edited): the points' checks, the same plants
    # and gains both times, are computed once (tests/computed_once.py: 5 s); the common certificate each time
    points_checked = computed_once(monkeypatch, monitor.checks.envelope, "verify_gains")
    capsys.readouterr()
    assert main(["verify", "--plant", str(env), "--gains", str(gains), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert {"stable", "points", "common_certificate", "gamma_common", "switching_sim_max"} <= set(report)
    assert (
        report["stable"] and report["common_certificate"] and report["gamma_common"] == pytest.approx(gf.common.gamma)
    )
    assert [p["name"] for p in report["points"]] == list(envelope.names)
    for p in report["points"]:
        assert {"name", "stable", "rho_max", "hinf_ef"} <= set(p) and p["stable"] and p["rho_max"] < 1
    assert 1.0 <= report["switching_sim_max"] < 1e3 and report["switching_sim_growth"] < 1.0
    # the common bound claimed smaller than the design found: some LMI fails, and verify says so
    text = gains.read_text()
    claimed = re.search(r"^gamma = (.*)$", text, flags=re.M)
    assert claimed is not None
    (tmp_path / "edited.toml").write_text(text.replace(claimed.group(0), f"gamma = {0.5 * float(claimed.group(1))}"))
    assert main(["verify", "--plant", str(env), "--gains", str(tmp_path / "edited.toml"), "--json"]) == 1
    refused = json.loads(capsys.readouterr().out)
    assert refused["common_certificate"] is False and refused["stable"] is False
    assert [p["stable"] for p in refused["points"]] == [True] * 3 and len(points_checked) == 3


def _pair_design(tmp_path: Path) -> tuple[Path, Path]:
    """The pair without a common P, with each point's own design and a common 'certificate' claimed by hand."""
    from monitor.design import run_design
    from monitor.design.envelope import CommonCertificate, EnvelopeDesign, point_vertices
    from monitor.design.solve import Solved
    from monitor.gains import write_envelope_gains

    env_file = tmp_path / "pair.toml"
    env_file.write_text(no_common_p_pair())
    env = load_envelope(env_file)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        results = {p.name: run_design("certified", p.plant) for p in env.points}
    N = 2 * 2 + 1 + 1
    claimed = CommonCertificate(
        P=np.eye(N),
        gamma=10.0,
        solved=Solved(path="by hand", status="claimed", margin=0.0),
        vertices={p.name: np.array([v.ravel() for v in point_vertices(p.plant)]) for p in env.points},
    )
    gains = tmp_path / "pair-gains.toml"
    write_envelope_gains(gains, EnvelopeDesign(envelope=env, method="certified", results=results, common=claimed))
    return env_file, gains


@pytest.mark.slow
def test_verify_refuses_points_stable_alone_without_a_common_p_and_the_switching_shows_the_growth(
    tmp_path: Path, capsys
) -> None:
    assert max(abs(np.linalg.eigvals(A1))) < 1 and max(abs(np.linalg.eigvals(A2))) < 1
    assert max(abs(np.linalg.eigvals(A1 @ A2))) > 1  # so alternating between them grows, and no common P exists
    env_file, gains = _pair_design(tmp_path)
    assert main(["verify", "--plant", str(env_file), "--gains", str(gains), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert all(p["stable"] and p["rho_max"] < 1 for p in report["points"])  # each point alone: fine
    assert report["common_certificate"] is False and report["stable"] is False
    assert report["switching_sim_growth"] > 1.5 and report["switching_sim_max"] > 1e100  # sqrt(2.93) per sample
    # the design finds no common P either, and names the pair (exit 1, one line)
    code = main(["design", "--plant", str(env_file), "--out", str(tmp_path / "g.toml"), "--jobs", "1", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1, err
    assert "no common Lyapunov matrix for points 'a' (airspeed 30) and 'b' (airspeed 40)" in err
    assert not (tmp_path / "g.toml").exists()


def test_the_common_lmi_and_the_pair_search_see_the_conflict() -> None:
    from monitor.design import run_design
    from monitor.design.envelope import _loops, common_certificate, conflicting_pairs, point_vertices

    env = parse_envelope(no_common_p_pair(), "pair.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loops = {
            p.name: _loops(p.plant, run_design("certified", p.plant).gains, point_vertices(p.plant)) for p in env.points
        }
        assert common_certificate(loops) is None
        assert conflicting_pairs(loops) == [("a", "b")]
        alone = common_certificate({"a": loops["a"]})
    assert alone is not None and alone[1] > 0  # each point alone has its P


@pytest.mark.slow
def test_single_point_plant_and_gains_go_through_design_and_verify_unchanged(tmp_path: Path, capsys) -> None:
    plant = tmp_path / "one.toml"
    plant.write_text((ROOT / "docs/examples/alpha-q-airframe.toml").read_text())
    gains = tmp_path / "gains.toml"
    assert main(["design", "--plant", str(plant), "--out", str(gains), "--quiet"]) == 0
    text = gains.read_text()
    assert text.startswith("[gains]\n") and "[envelope]" not in text and "[point." not in text
    assert main(["verify", "--plant", str(plant), "--gains", str(gains), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["stable"] and report["certificate_valid"] and "points" not in report
    from monitor.gains import read_envelope_gains

    with pytest.raises(UserError, match="is a single-point gains file"):
        read_envelope_gains(gains)
    env = tmp_path / "env.toml"
    env.write_text(envelope_text(*_three()))
    assert main(["verify", "--plant", str(env), "--gains", str(gains)]) == 2
    assert "is a single-point gains file" in capsys.readouterr().err


@pytest.mark.slow
def test_the_documented_example_is_an_envelope_that_designs_and_verifies() -> None:
    from monitor.checks.envelope import CommonClaim, PointClaim, verify_envelope
    from monitor.design.envelope import design_envelope

    env = parse_envelope(documented_envelope(), "docs/explanation/envelope.md")
    assert env.names == ("approach", "cruise") and env.schedule == ("airspeed",)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        design = design_envelope(env, jobs=1)
    assert not design.redesigned
    claims = {n: PointClaim(r.certificate, r.gamma_e, r.gamma_z) for n, r in design.results.items()}
    common = CommonClaim(P=design.common.P, gamma=design.common.gamma, vertices=design.common.vertices)
    verdict = verify_envelope(env, {n: r.gains for n, r in design.results.items()}, claims, common)
    assert verdict.stable and verdict.common_certificate and all(p.verdict.certificate_valid for p in verdict.points)
