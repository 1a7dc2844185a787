"""``verify`` says which gains it judged, including the K2/K3 it assumed when they were not given."""

from __future__ import annotations

import json
import subprocess
import sys


def _verify(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "verify",
            "--plant",
            "paper",
            "--L",
            "1.87,1.63",
            "--M",
            "0.9",
            "--K1",
            "-0.5",
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_verify_prints_every_gain_and_marks_the_assumed_ones() -> None:
    table = _verify().stdout
    for name in ("L", "M", "K1", "K2", "K3"):
        assert any(line.strip().startswith(name + " ") for line in table.splitlines()), table
    assert table.count("(assumed: Lemma 3") == 2
    report = json.loads(_verify("--K2", "0.1", "--json").stdout)
    assert report["assumed"] == ["K3"] and report["gains"]["K2"] == [[0.1]] and report["gains"]["L"] == [[1.87], [1.63]]
