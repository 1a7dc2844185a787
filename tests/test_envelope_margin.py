"""``fault-monitor margin`` on an envelope: every point's delay margin (the single-point search on the point's own
plant), the worst, and the common certificate at it; one line for what an envelope does not take."""

from __future__ import annotations

import json

import pytest

from monitor.cli import main
from monitor.model.envelope import load_envelope
from tests.computed_once import computed_once
from tests.daemons import REPO

pytestmark = pytest.mark.slow

ENVELOPE = REPO / "tests" / "data" / "c172p-envelope-90-100kt.toml"


def test_each_point_s_margin_is_its_own_search_and_the_envelope_takes_the_worst(capsys, monkeypatch) -> None:
    import monitor.checks.envelope_margin

    # the command's search at each point is remembered (tests/computed_once.py): the check below asks for the same
    # search on the point's own plant and gets it from there, unless the command searched on another plant or with
    # other options, which are then searched for real and compared (two searches of 4 s saved, not their check)
    searched = computed_once(monkeypatch, monitor.checks.envelope_margin, "delay_margin")
    code = main(["margin", "--plant", str(ENVELOPE), "--jobs", "1", "--tolerance", "0.002", "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    doc = json.loads(out)
    envelope = load_envelope(ENVELOPE)
    margins = {p["name"]: p["tau_max"] for p in doc["points"]}
    assert list(margins) == list(envelope.names)
    search = monitor.checks.envelope_margin.delay_margin
    for point in envelope.points:  # the same search as the single-point command's, on the point's own plant
        alone = search(point.plant, tolerance=0.002, curve_points=2, objective="fast")
        assert margins[point.name] == pytest.approx(alone.tau_max, abs=1e-12)
        assert margins[point.name] >= envelope.tau_max  # the file's interval is certified, so the margin is above it
    assert doc["worst"] == min(margins, key=margins.__getitem__) and doc["tau_max"] == min(margins.values())
    assert doc["common_certificate"] is True and doc["gamma_common"] > 0 and doc["why_not"] is None
    assert len(searched) == len(envelope.points)  # the command searched each point as the check does


@pytest.mark.parametrize("extra", [["--up-to", "0.1"], ["--png", "m.png"], ["--jobs", "0"]])
def test_what_an_envelope_margin_does_not_take_is_one_line(extra: list[str], capsys) -> None:
    assert main(["margin", "--plant", str(ENVELOPE), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fault-monitor margin: error: --")


def test_jobs_on_a_single_plant_is_one_line(capsys) -> None:
    assert main(["margin", "--plant", "paper", "--jobs", "2"]) == 2
    assert "--jobs and --scheduler are for an envelope plant's points" in capsys.readouterr().err
