"""``--config FILE.toml`` (monitor.config_file) and ``--log-level`` on every sub-command, on the real parsers."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from monitor.cli import build_parser as monitor_parser
from monitor.config_file import config_defaults, parse_args_with_config, read_config
from monitor.errors import UserError
from sim_vehicle.cli import build_parser as vehicle_parser
from tests.readme_blocks import file_block

REPO = Path(__file__).resolve().parent.parent


def _sub(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]


def test_the_readme_monitor_file_sets_run_flags_and_flags_still_win(tmp_path):
    conf = tmp_path / "monitor.toml"
    conf.write_text(file_block("monitor.toml").text)  # the block marked <!-- readme: file monitor.toml -->
    parser = monitor_parser()
    args = parse_args_with_config(
        parser,
        [
            "run",
            "--config",
            str(conf),
            "--name",
            "from-flag",
            "--mavlink",
            "udpin:127.0.0.1:14551",
            "--mavlink",
            "udpin:127.0.0.1:14552",
        ],
    )
    assert args.plant == "paper-continuous" and args.gains == "/etc/fault-monitor/gains.toml"
    assert args.zenoh_listen == ["tcp/127.0.0.1:7447"] and args.alarm_threshold == 1.0
    assert args.rrd == "/var/lib/fault-monitor/run.rrd" and args.log_level == "INFO"
    assert args.name == "from-flag"  # the command line wins over the file
    # a repeatable flag given on the command line replaces the file's whole list, as any other flag does
    assert args.mavlink == ["udpin:127.0.0.1:14551", "udpin:127.0.0.1:14552"]
    kept = parse_args_with_config(monitor_parser(), ["run", "--config", str(conf)])
    assert kept.mavlink == ["udpin:127.0.0.1:14550"]  # not given: the file's list
    page = (REPO / file_block("monitor.toml").page).read_text()  # docs/how-to/configuration.md
    assert "systemd" in page and "fault-monitor run --config /etc/fault-monitor/monitor.toml" in page


def test_keys_take_either_spelling_switches_and_lists():
    run = _sub(monitor_parser(), "run")
    got = config_defaults(
        run,
        {
            "no-truth": True,
            "no_gcs_feedback": True,
            "observe": False,
            "zenoh-connect": "tcp/127.0.0.1:7447",
            "alarm-samples": 3,
        },
        "m.toml",
    )
    assert got == {
        "truth": False,
        "gcs_feedback": False,
        "observe": False,
        "zenoh_connect": ["tcp/127.0.0.1:7447"],
        "alarm_samples": 3,
    }
    vehicle = _sub(vehicle_parser(), "run")
    assert config_defaults(vehicle, {"x0": [0.1, 0], "autopilot": [-2.5]}, "v.toml") == {
        "x0": "0.1,0",
        "autopilot": "-2.5",
    }


@pytest.mark.parametrize(
    "raw, message",
    [
        ({"dealy": "const:0.1"}, "unknown key 'dealy'"),
        ({"alarm_threshold": "high"}, "key 'alarm_threshold': expected a number or 'auto', got 'high'"),
        ({"alarm_samples": 2.5}, "key 'alarm_samples': expected an integer"),
        ({"observe": "yes"}, "key 'observe': expected true or false"),
        ({"mavlink": [1]}, None),  # a number where a string is expected is taken as its text (then validated by run)
        ({"zenoh_mode": "server"}, "is not one of peer, client, router"),
        ({"log_level": "LOUD"}, "is not one of DEBUG"),
        ({"help": True}, "unknown key 'help'"),
        ({"func": "x"}, "unknown key 'func'"),
    ],
)
def test_bad_keys_and_values_are_one_line_naming_key_and_file(raw, message):
    run = _sub(monitor_parser(), "run")
    if message is None:
        assert config_defaults(run, raw, "m.toml") == {"mavlink": ["1"]}
        return
    with pytest.raises(UserError) as exc:
        config_defaults(run, raw, "/etc/m.toml")
    text = str(exc.value)
    assert "\n" not in text and "--config /etc/m.toml" in text and message in text


def test_unreadable_and_invalid_files(tmp_path):
    with pytest.raises(UserError, match="cannot read"):
        read_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("plant = \n")
    with pytest.raises(UserError, match="not valid TOML"):
        read_config(bad)


def test_parse_args_with_config_presets_the_chosen_sub_command(tmp_path):
    conf = tmp_path / "v.toml"
    conf.write_text('steps = 3\nspeedup = 20\nno_zenoh = true\nlog-level = "debug"\n')
    args = parse_args_with_config(vehicle_parser(), ["run", "--config", str(conf), "--steps", "5"])
    assert (args.steps, args.speedup, args.no_zenoh, args.log_level) == (5, 20.0, True, "DEBUG")


@pytest.mark.parametrize("build", [monitor_parser, vehicle_parser])
def test_log_level_before_or_after_every_sub_command(build):
    parser = build()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    for name, sub in subs.items():
        assert "--log-level" in sub._option_string_actions, name
    for name in ("run", "subscribe") if "subscribe" in subs else ("run",):
        assert parser.parse_args([name, "--log-level", "warning"]).log_level == "WARNING", name
        assert parser.parse_args(["--log-level", "DEBUG", name]).log_level == "DEBUG", name
        assert parser.parse_args([name]).log_level == "INFO", name


def test_unknown_config_key_exits_2_with_one_line(tmp_path):
    conf = tmp_path / "v.toml"
    conf.write_text('plant = "paper-continuous"\ndealy = "const:0.1"\n')
    proc = subprocess.run(
        [sys.executable, "-m", "sim_vehicle", "run", "--config", str(conf)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "unknown key 'dealy'" in proc.stderr and str(conf) in proc.stderr
