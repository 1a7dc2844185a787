"""The README and the documentation pages are a test: every code block of ``README.md`` and of every page under
``docs/`` carries a marker (``tests/readme_blocks.py``), and every block marked ``run`` runs as a user types it, under
the harness's rewrites (free ports, fewer and faster samples): the paper and router groups here, the others in the
tests ``RUN_GROUPS`` names (the notebook block in ``tests/test_api.py``).
"""

from __future__ import annotations

import importlib
import json
import os
import re
import shutil
import signal
import tomllib
from pathlib import Path

import pytest

from tests.daemons import wait_for
from tests.dataflash_formats import FORMATS
from tests.readme_blocks import (
    README,
    Block,
    Session,
    blocks,
    check_command_parses,
    group,
    indented_code_lines,
    page_name,
    pages,
)

# every group of run blocks and the test that runs it: a group added to a page without a test fails here
RUN_GROUPS = {
    "paper": "tests/test_readme.py::test_paper_daemons_then_the_replay_of_their_recording",
    "router": "tests/test_readme.py::test_router_its_clients_and_a_python_subscriber",
    "mavproxy": "tests/e2e/test_mavproxy.py::test_the_readme_block_closes_the_loop_through_mavproxy",
    "aircraft": "tests/e2e/test_aircraft_chain.py::test_excite_identify_design_and_close_the_loop_on_jsbsim",
    "notebook": "tests/test_api.py::test_the_readme_python_block_runs_as_it_stands_in_a_fresh_directory",
    "long-delay": "tests/e2e/test_multi_delay_loop.py::test_the_readme_long_delay_blocks_estimate_and_hold",
}


def test_the_pages_are_the_readme_and_every_docs_page() -> None:
    names = [page_name(p) for p in pages()]
    assert names[0] == "README.md" and "docs/index.md" in names and "docs/layout.md" in names, names
    assert all(n.startswith("docs/") and n.endswith(".md") for n in names[1:]), names
    # the blocks that used to be the README's are still checked wherever they now live
    assert {b.arg("group") for b in blocks() if b.kind == "run"} >= {"paper", "router", "mavproxy", "notebook"}
    assert {b.page for b in blocks()} - {"README.md"}, "no docs page has a block: pages() lost docs/"


def test_every_block_carries_a_marker() -> None:
    problems = [f"{b.where}: {b.problem()}" for b in blocks() if b.problem()]
    problems += [
        f"{page_name(page)}:{line}: a code block indented by four spaces can carry no marker: fence it (```)"
        for page in pages()
        for line in indented_code_lines(page)
    ]
    assert not problems, "\n".join(problems)


def test_the_readme_keeps_the_ci_test_command() -> None:
    """.ci/run runs the line after the ci:test-command marker, which must be the bash block's command."""
    lines = README.read_text("utf-8").splitlines()
    (at,) = [i for i, line in enumerate(lines) if "ci:test-command" in line]
    assert lines[at + 1] == "```bash" and lines[at + 2].startswith("python -m pip install -c constraints.txt '.[test]'")


def test_every_run_group_has_its_test() -> None:
    groups = {b.arg("group") for b in blocks() if b.kind == "run"}
    assert groups == set(RUN_GROUPS), (
        f"run groups without a test: {sorted(groups - set(RUN_GROUPS))}; "
        f"tests without a group: {sorted(set(RUN_GROUPS) - groups)}"
    )
    for node in RUN_GROUPS.values():  # each named test exists (a rename must follow here)
        path, name = node.split("::")
        module = importlib.import_module(path.removesuffix(".py").replace("/", "."))
        assert callable(getattr(module, name, None)), f"{node} does not exist"


def _not_run_commands() -> list[tuple[Block, int, str]]:
    found = []
    for block in blocks():
        if block.lang != "bash":
            continue
        skip = block.arg("skip")
        for line, command in block.commands():
            if block.kind == "not run" or (skip and command.startswith(skip)):
                found.append((block, line, command))
    return found


def test_commands_not_run_still_parse() -> None:
    """Flags of blocks that are not run exist and take the values given (the real parsers, nothing executed)."""
    problems = [
        f"{block.page}:{line}: {command}\n  {complaint}"
        for block, line, command in _not_run_commands()
        if (complaint := check_command_parses(command))
    ]
    assert not problems, "\n".join(problems)
    assert len(_not_run_commands()) >= 8  # the parse check is not silently empty


# the DataFlash messages the ArduPlane map (docs/tutorials/flight-logs.md) names: those tests/test_dataflash.py
# writes, and the pitch controller's PIDP as ArduPlane 4.x declares it in its FMT record
ARDUPLANE_FORMATS = {**FORMATS, "PIDP": (136, "QffffffffffB", "TimeUS,Tar,Act,Err,P,I,D,FF,DFF,Dmod,SRate,Flags")}


def _layouts(kind: str):
    if kind == "mavlink":
        from monitor.link.signals import MAVLINK

        return MAVLINK
    if kind == "ulog":
        from monitor.link.ulog import open_ulog

        return open_ulog(Path(__file__).parent / "data" / "ulog" / "sample_log_small.ulg").layouts
    from pymavlink.DFReader import DFFormat

    from monitor.link.dataflash import DataFlashLayouts

    formats = {name: DFFormat(t, name, 0, fmt, cols) for name, (t, fmt, cols) in ARDUPLANE_FORMATS.items()}
    return DataFlashLayouts(formats, {name: t for name, (t, _f, _c) in ARDUPLANE_FORMATS.items()})


@pytest.mark.parametrize("block", [b for b in blocks() if b.kind == "signals"], ids=lambda b: b.where)
def test_signal_maps_are_read_by_the_map_reader(block: Block) -> None:
    """A map with ``outputs`` as run and analyse read it (for a plant with as many outputs as C has rows, when the
    block shows C); one without, as identify reads it for each of its models."""
    from monitor.link.signals import parse_signals
    from monitor.model.identification import MODELS
    from monitor.pipelines.identify_log import map_for

    raw = tomllib.loads(block.text)
    table, where, layouts = raw["signals"], block.where, _layouts(block.arg("layouts"))
    if "outputs" not in table:
        for states in MODELS.values():
            assert map_for(table, where, states, layouts)[0].outputs == states
        return
    outputs = len(raw["C"]) if "C" in raw else len(table["outputs"])
    smap = parse_signals(table, where, outputs, len(table["actuator"]), layouts)
    assert smap.outputs == tuple(table["outputs"])


@pytest.mark.parametrize("block", [b for b in blocks() if b.kind == "file"], ids=lambda b: b.arg("name"))
def test_files_parse(block: Block) -> None:
    if block.arg("name").endswith(".toml"):
        assert tomllib.loads(block.text), f"{block.where}: an empty file"


# -- the run groups -------------------------------------------------------------------------------------------------

STEPS, SPEEDUP = 40, 25  # each flight of the paper plant (h = 1 s): 40 samples at 25x, 1.6 s; the bias starts at k = 20


def _json_lines(text: str) -> list[dict]:
    """The complete lines of a file still being written (its last, unfinished line is left for later)."""
    return [json.loads(line) for line in text.split("\n")[:-1] if line.strip()]


def _printed_last_sample(text: str) -> bool:
    return any(e["k"] == STEPS - 1 for e in _json_lines(text))


def test_paper_daemons_then_the_replay_of_their_recording(tmp_path: Path) -> None:
    """Design, monitor, subscriber and vehicle, each as in a terminal of its own; Ctrl-C; then replay the recording."""
    daemons, replay = group("paper")
    with Session(tmp_path, steps=STEPS, speedup=SPEEDUP) as s:
        design, monitor, subscriber, _flight = s.run(daemons)
        assert "certificate" in design.out() and (s.dir / "gains.toml").exists(), design.failure("no gains file")
        wait_for(lambda: _printed_last_sample(subscriber.out()), 10, what="the subscriber to print the last sample")
        s.stop()
        estimates = _json_lines(subscriber.out())
        assert {e["sysid"] for e in estimates} == {1} and any(e["alarm"] for e in estimates), subscriber.failure("")
        assert abs(estimates[-1]["f_hat"][0] - 2.0) < 0.1, subscriber.failure("the 2-degree bias not estimated")
        assert f"samples processed {STEPS}" in monitor.err(), monitor.failure("not every sample processed")

        plain, as_json, with_spec = s.run(replay)
        assert f"{STEPS} samples" in plain.out() and "(from the recorded truth)" in plain.out(), plain.failure("")
        report = json.loads(as_json.out())
        assert report["samples"] == STEPS and report["settling_steps"] is not None, as_json.failure("")
        assert "(from SPEC bias:2@20)" in with_spec.out(), with_spec.failure("not scored against the SPEC")
        s.assert_ran_all("paper")


def _wait_subscribed(endpoint: str, key: str) -> None:
    """Until a subscriber matches ``key`` (a publisher's matching status; nothing is published)."""
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    session = open_session(build_config(connect=[endpoint], mode="client"))
    try:
        publisher = session.declare_publisher(key)
        wait_for(lambda: publisher.matching_status.matching, 20, what=f"a subscriber to {key}")
    finally:
        close_quietly(session)


def test_router_its_clients_and_a_python_subscriber(tmp_path: Path, gains_file: Path) -> None:
    """The router block; then, as late joiners, the zenoh-python script and the bundled clients, while the vehicle
    flies again (the same command): each sees the monitor through the router."""
    routed, bundled, script = group("router")
    with Session(tmp_path, steps=STEPS, speedup=SPEEDUP) as s:
        shutil.copy(gains_file, s.dir / "gains.toml")  # the design line of the paper group (run by its test)
        _router, _monitor, subscriber, flight = s.run(routed)
        wait_for(lambda: _printed_last_sample(subscriber.out()), 10, what="the subscriber to print the last sample")
        (python,) = s.run(script)
        wait_for(lambda: re.search(r"^status (.*)\n", python.out(), re.M), 15, what="the script's late joiner's status")
        status = json.loads(re.search(r"^status (.*)\n", python.out(), re.M).group(1))
        assert status["sysid"] == 1 and status["k"] == STEPS - 1, python.failure("not the last sample's status")
        every, alarm, timed = s.run(bundled, background=True)
        _wait_subscribed(f"tcp/127.0.0.1:{s.port(7447)}", "uav/1/fault/alarm")  # else a slow start misses it
        s.again(flight)
        alarm.wait(20)
        timed.wait(20)
        wait_for(lambda: f"\n1 {STEPS - 1} " in python.out(), 10, what="the script to print the second flight")
        os.killpg(every.proc.pid, signal.SIGTERM)  # as systemd stops it: exit 0 too
        assert every.proc.wait(15) == 0, every.failure("exit code after SIGTERM")
        s.stop()
        s.assert_ran_all("router")
    raised = _json_lines(alarm.out())
    assert len(raised) == 1 and raised[0]["state"] == "raised", alarm.failure("not one alarm, then exit (--count 1)")
    assert _printed_last_sample(every.out()), every.failure("the second flight's last sample is missing")
    assert {e["sysid"] for e in _json_lines(every.out())} == {1}
    assert _printed_last_sample((s.dir / "estimates.jsonl").read_text()), timed.failure("estimates.jsonl lacks it")
