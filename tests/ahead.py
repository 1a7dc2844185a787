"""Commands a paced end-to-end test needs the output of, started ahead of it at a low CPU priority.

Why: the serial ``e2e-daemons`` group (``tests/conftest.py``) is the suite's critical path, and its loops spend
most of their time waiting on the wall clock. ``tests/e2e/test_multi_delay_aircraft.py`` first designs and
verifies its long-delay plant with the README's commands (64 delay vertices: some 17 s of CPU in that group, on
nothing paced) and only then flies; the turbulence and compensation flights design first too (3 s each). Started
when the group's first test starts, at ``nice 19`` (a paced daemon that wakes takes the core back at once), the
commands use the time the group's loops leave idle; each test reads their output when it comes to it. The same
commands and the same outputs, each computed for real once.

``ahead(name)`` waits (bounded) for job ``name`` and returns its commands' results and its directory. When the job
is still running then, it gets its priority back (root: the machines that run the suite; else it is run again at
once, as the test would have run it). When nothing started it (the test run alone), it starts there.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from monitor.process import stop_process_group

REPO = Path(__file__).resolve().parent.parent
LONG_DELAY_PLANT = str(REPO / "tests" / "data" / "c172p-longitudinal-long-delay.toml")
TURBULENCE_PLANT = str(REPO / "tests" / "data" / "c172p-longitudinal-turbulence.toml")


def _monitor(*args: str) -> list[str]:
    return [sys.executable, "-m", "monitor", *args]


# job -> (the test file that needs it, its commands run one after another in the job's directory)
JOBS: dict[str, tuple[str, list[list[str]]]] = {
    "long-delay": (
        "tests/e2e/test_multi_delay_aircraft.py",
        [
            _monitor("design", "--plant", LONG_DELAY_PLANT, "--out", "gains.toml"),
            _monitor("verify", "--plant", LONG_DELAY_PLANT, "--gains", "gains.toml"),
        ],
    ),
    "turbulence": (
        "tests/e2e/test_turbulence.py",
        [_monitor("design", "--plant", TURBULENCE_PLANT, "--out", "gains.toml")],
    ),
    "compensate": (  # the raw estimate: the compensation acts on it
        "tests/e2e/test_compensate_mission.py",
        [_monitor("design", "--plant", TURBULENCE_PLANT, "--fault-time-constant", "0", "--out", "gains.toml")],
    ),
}
NICE = 19
WAIT_S = 300.0


class Job:
    """Commands run one after another (stopping at the first that fails) in a directory of their own, on a thread."""

    def __init__(self, commands: list[list[str]], nice: int) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="ahead-"))
        self.commands = commands
        self.nice = nice
        self.results: list[subprocess.CompletedProcess] = []
        self.proc: subprocess.Popen | None = None
        self.cancelled = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        for argv in self.commands:
            if self.cancelled:
                return
            prefix = ["nice", "-n", str(self.nice)] if self.nice and shutil.which("nice") else []
            self.proc = subprocess.Popen(
                [*prefix, *argv],
                cwd=self.folder,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                start_new_session=True,  # its own process group: stop() ends whatever it started
            )
            out, err = self.proc.communicate()
            self.results.append(subprocess.CompletedProcess(argv, self.proc.returncode, out, err))
            if self.proc.returncode != 0:
                return

    def hurry(self) -> bool:
        """Give the running command back the default priority; False when that is not allowed."""
        nice, self.nice = self.nice, 0  # the commands not started yet run at the default priority
        proc = self.proc
        if nice == 0 or proc is None or proc.poll() is not None:
            return True
        try:
            os.setpriority(os.PRIO_PGRP, proc.pid, 0)
        except PermissionError:
            return False
        except ProcessLookupError:  # it has just finished
            pass
        return True

    def stop(self) -> None:
        self.cancelled = True
        if self.proc is not None and self.proc.poll() is None:
            stop_process_group(self.proc, timeout=5.0)
        self.thread.join(10)
        shutil.rmtree(self.folder, ignore_errors=True)


_started: dict[str, Job] = {}


def start(needed_by: set[str]) -> None:
    """Start every job a test file of ``needed_by`` (paths from the repository's top) needs, once per session."""
    for name, (test_file, commands) in JOBS.items():
        if name not in _started and test_file in needed_by:
            _started[name] = Job(commands, NICE)


_looked = False


def start_for_session(items: list) -> None:
    """The hook's call (the serial group's first test): the jobs of every test file the session will run."""
    global _looked
    if not _looked:
        _looked = True
        start({Path(str(item.fspath)).resolve().relative_to(REPO).as_posix() for item in items})


def ahead(name: str) -> tuple[list[subprocess.CompletedProcess], Path]:
    """Job ``name``'s results (one per command run) and its directory, once it has finished."""
    job = _started.get(name)
    if job is None:
        start({JOBS[name][0]})
        job = _started[name]
    if not job.hurry():  # not allowed to raise its priority: run it again now, at the test's own
        job.stop()
        job = _started[name] = Job(JOBS[name][1], 0)
    job.thread.join(WAIT_S)
    assert not job.thread.is_alive(), f"job {name} still running after {WAIT_S:.0f} s: {job.commands}"
    return job.results, job.folder


def designed_ahead(name: str, gains: Path) -> list[subprocess.CompletedProcess]:
    """Job ``name`` (a `design`, then maybe more) once finished: its design succeeded and wrote ``gains`` (copied
    there from the job's directory); its commands' results."""
    done, folder = ahead(name)
    design = done[0]
    assert design.returncode == 0, design.stdout[-2000:] + design.stderr[-2000:]
    shutil.copy(folder / "gains.toml", gains)
    return done


def stop_all() -> None:
    """At the session's end: whatever is still running is stopped, every directory removed."""
    while _started:
        _started.popitem()[1].stop()
