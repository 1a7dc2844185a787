"""The code blocks of the README and of every documentation page (``docs/**/*.md``), the marker that says how the
suite checks each one, and a harness that runs the blocks marked ``run`` as a user types them.

The pages are ``README.md`` and every ``*.md`` under ``docs/`` (``pages()``), in that order: README first, then the
docs pages sorted by path, each page's blocks in their order there; a run group's blocks are taken in that order
(a group may span pages). Every page follows the same rules: each fenced block carries a marker, and no code block
is indented (it could carry none).

The marker is an HTML comment (neither GitHub nor the site shows it) among the comment lines directly above the
opening fence:

    <!-- readme: run GROUP -->               run by GROUP's test (tests/test_readme.py's RUN_GROUPS names each)
    <!-- readme: run GROUP; not run: CMD (REASON) -->   the same, except the lines that start with CMD
    <!-- readme: file NAME -->               a file the user saves as NAME: parsed, and present in every run directory
    <!-- readme: signals mavlink -->         a [signals] table, read by the project's own map reader (the MAVLink
    <!-- readme: signals dataflash -->       dialect, an ArduPilot DataFlash log's messages, or the topics of
    <!-- readme: signals ulog -->            PX4's ULog sample tests/data/ulog/sample_log_small.ulg)
    <!-- readme: output -->                  nothing to type: what a program prints, a diagram, a listing
    <!-- readme: not run: REASON -->         not run, for REASON; its fault-monitor and sim-vehicle lines must still
                                             parse with the real argument parsers

How a ``run`` block runs (``Session``): in a temporary directory, one command (a line with its ``\\`` continuations)
after another, each through ``bash -c``. A command that ends in ``&``, or that runs until it is stopped (``fault-monitor
run``, ``router``, ``subscribe`` without ``--count``/``--duration``, ``mavproxy.py``, a Python block with ``while
True``), starts in the background in its own process group, as in a terminal of its own, and is waited for until it is
ready (its ``ready:`` line; MAVProxy: its port taken); any other command must exit 0 within a bounded wait. Everything
started is stopped when the session ends: SIGINT (Ctrl-C), then SIGTERM and SIGKILL to its process group.

What the harness rewrites, and nothing else:

* ports: each fixed loopback port of the pages (``127.0.0.1:PORT``) becomes a free port picked for the session, the
  same one in every block and file of the session; a command that relies on a default port (``sim-vehicle run`` and
  ``fault-monitor run`` without ``--mavlink``: 14550; ``fault-monitor router`` without ``-l``: 7447) has it spelled
  out, with its substitute;
* speed: ``--steps N`` becomes min(N, steps), ``--speedup S`` max(S, speedup) and subscribe's ``--duration S``
  min(S, duration), with the values the group's test gives its session (None: as written), block by block;
* Python's output is unbuffered (``PYTHONUNBUFFERED=1``), as a terminal shows a script's lines when printed.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from monitor.process import udp_port_taken
from tests.daemons import REPO, free_udp_port, wait_for

README = REPO / "README.md"
DOCS = REPO / "docs"


def pages() -> tuple[Path, ...]:
    """The pages whose blocks the suite checks: the README, then every Markdown page under docs/ by path."""
    return (README, *sorted(DOCS.rglob("*.md")))


def page_name(path: Path) -> str:
    """A page as the messages name it: its path from the repository's top (``docs/how-to/zenoh.md``)."""
    resolved = path.resolve()
    return resolved.relative_to(REPO).as_posix() if resolved.is_relative_to(REPO) else str(path)


_MARKER = re.compile(r"<!--\s*readme:\s*(.*?)\s*-->")
_COMMENT_LINE = re.compile(r"^\s*<!--.*-->\s*$")
_FENCE = re.compile(r"^```(\S*)\s*$")
_KINDS = {
    "run": re.compile(r"run (?P<group>[\w-]+)(?:; not run: (?P<skip>[^(]+?) \((?P<why>[^)]+)\))?"),
    "file": re.compile(r"file (?P<name>\S+)"),
    "signals": re.compile(r"signals (?P<layouts>mavlink|dataflash|ulog)"),
    "output": re.compile(r"output"),
    "not run": re.compile(r"not run: (?P<why>\S.*)"),
}


@dataclass(frozen=True)
class Block:
    """One fenced block: the line of its opening fence (1-based), its language, its text, its marker and the page
    it is on (its path from the repository's top)."""

    line: int
    lang: str
    text: str
    marker: str | None
    page: str = "README.md"

    @property
    def where(self) -> str:
        """``PAGE:LINE`` of the opening fence, as the messages name it."""
        return f"{self.page}:{self.line}"

    def _match(self) -> tuple[str, dict[str, str]] | None:
        for kind, pattern in _KINDS.items():
            found = pattern.fullmatch(self.marker or "")
            if found:
                return kind, {k: v for k, v in found.groupdict().items() if v is not None}
        return None

    @property
    def kind(self) -> str | None:
        """run, file, signals, output or not run; None when unmarked or the marker is not one of those."""
        match = self._match()
        return match[0] if match else None

    def arg(self, name: str) -> str | None:
        """A field of the marker: group and skip (run), name (file), layouts (signals), why (not run)."""
        match = self._match()
        return match[1].get(name) if match else None

    def problem(self) -> str | None:
        if self.marker is None:
            return (
                "no marker: put <!-- readme: run GROUP | file NAME | signals mavlink | output | not run: REASON --> "
                "on the line above the fence (tests/readme_blocks.py)"
            )
        if self.kind is None:
            return f"unknown marker '{self.marker}' (see tests/readme_blocks.py)"
        return None

    def commands(self) -> list[tuple[int, str]]:
        """Each command of a shell block with the page's line it starts on: continuations joined, comments and
        blank lines left out."""
        out: list[tuple[int, str]] = []
        pending: list[str] = []
        start = 0
        for offset, raw in enumerate(self.text.splitlines(), start=self.line + 1):
            if not pending and (not raw.strip() or raw.lstrip().startswith("#")):
                continue
            if not pending:
                start = offset
            if raw.rstrip().endswith("\\"):
                pending.append(raw.rstrip()[:-1])
                continue
            out.append((start, " ".join(part.strip() for part in [*pending, raw])))
            pending = []
        return out


@cache
def blocks(path: Path | None = None) -> tuple[Block, ...]:
    """Every fenced block of one page, in order; without a page, every block of every page (``pages()``)."""
    if path is None:
        return tuple(b for page in pages() for b in blocks(page))
    lines = path.read_text("utf-8").splitlines()
    name = page_name(path)
    found: list[Block] = []
    i = 0
    while i < len(lines):
        opening = _FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), None)
        if end is None:
            raise ValueError(f"{name}:{i + 1}: a fence that is never closed")
        marker, above = None, i - 1
        while above >= 0 and _COMMENT_LINE.match(lines[above]):
            tag = _MARKER.search(lines[above])
            marker = tag.group(1) if tag else marker
            above -= 1
        text = "".join(line + "\n" for line in lines[i + 1 : end])
        found.append(Block(i + 1, opening.group(1), text, marker, name))
        i = end + 1
    return tuple(found)


def indented_code_lines(path: Path) -> list[int]:
    """Lines that open a code block by indentation (four spaces after a blank line, outside a fence): such a
    block can carry no marker, so it must be fenced."""
    lines = path.read_text("utf-8").splitlines()
    inside, found = False, []
    for i, line in enumerate(lines):
        if line.startswith("```"):
            inside = not inside
        elif not inside and line.startswith("    ") and line.strip() and i > 0 and not lines[i - 1].strip():
            found.append(i + 1)
    return found


def group(name: str) -> list[Block]:
    """The blocks marked ``run NAME``, in page order (``pages()``) and in order on each page."""
    return [b for b in blocks() if b.kind == "run" and b.arg("group") == name]


def file_block(name: str) -> Block:
    (block,) = [b for b in blocks() if b.kind == "file" and b.arg("name") == name]
    return block


# -- the harness ----------------------------------------------------------------------------------------------------

_LOOPBACK_PORT = re.compile(r"(?<=127\.0\.0\.1:)(\d{2,5})\b")
_DEFAULT_PORTS = (  # (command, flags that name the port instead, the flag and address it defaults to)
    (re.compile(r"^sim-vehicle run\b"), ("--mavlink", "--config"), "--mavlink udpout:127.0.0.1:{14550}"),
    (re.compile(r"^fault-monitor run\b"), ("--mavlink", "--config", "--fleet"), "--mavlink udpin:127.0.0.1:{14550}"),
    (re.compile(r"^fault-monitor router\b"), ("-l", "--listen", "-c", "--config"), "-l tcp/127.0.0.1:{7447}"),
)
_LONG_LIVED = re.compile(
    r"^(fault-monitor (run|router)\b|mavproxy\.py\b|sim-vehicle run\b(?!.*--steps)"
    r"|fault-monitor subscribe\b(?!.*--(count|duration)))"
)
_OURS = re.compile(r"^(fault-monitor|sim-vehicle)\b")


def _free_port() -> int:
    """A loopback port free for both UDP and TCP (the pages use some ports for each)."""
    while True:
        port = free_udp_port()
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port


@dataclass
class Step:
    """One command (or Python block) started by a session."""

    block: Block
    line: int  # the line of its page it starts on
    command: str  # as run, after the rewrites
    proc: subprocess.Popen
    out_path: Path
    err_path: Path
    background: bool
    returncode: int | None = None

    def out(self) -> str:
        return self.out_path.read_text(errors="replace")

    def err(self) -> str:
        return self.err_path.read_text(errors="replace")

    def where(self) -> str:
        return f"{self.block.page}:{self.line}: {self.command}"

    def failure(self, what: str) -> str:
        return f"{self.where()}\n{what}\nstdout:\n{self.out()[-2000:]}\nstderr:\n{self.err()[-3000:]}"

    def wait(self, timeout: float) -> int:
        """Wait (bounded) for a command that ends by itself; it must exit 0."""
        try:
            self.returncode = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(self.failure(f"still running after {timeout:.0f} s")) from None
        assert self.returncode == 0, self.failure(f"exit code {self.returncode}")
        return self.returncode


@dataclass
class Session:
    """One group's run: a working directory, the port map, and every process started (stopped at the end)."""

    tmp: Path
    steps: int | None = 40
    speedup: float | None = 25.0
    duration: float = 5.0
    timeout: float = 90.0  # the longest any one command may take
    ports: dict[int, int] = field(default_factory=dict)
    steps_run: list[Step] = field(default_factory=list)
    blocks_run: list[Block] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.dir = self.tmp / "work"
        self.logs = self.tmp / "logs"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.logs.mkdir(exist_ok=True)
        bin_dir = str(Path(sys.executable).parent)  # the console scripts of this interpreter's environment
        self.env = {
            **os.environ,
            "PATH": bin_dir + os.pathsep + os.environ.get("PATH", ""),
            "RERUN_ANALYTICS": "0",
            "PYTHONUNBUFFERED": "1",
        }
        for block in blocks():
            if block.kind == "file":
                (self.dir / Path(block.arg("name")).name).write_text(self.rewrite_ports(block.text))

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        for step in reversed(self.steps_run):
            _end(step, signal.SIGTERM, 5.0)

    # the rewrites ---------------------------------------------------------------------------------------------------
    def port(self, page_port: int) -> int:
        if page_port not in self.ports:
            self.ports[page_port] = _free_port()
        return self.ports[page_port]

    def rewrite_ports(self, text: str) -> str:
        return _LOOPBACK_PORT.sub(lambda m: str(self.port(int(m.group(1)))), text)

    def rewrite(self, command: str) -> str:
        command = self.rewrite_ports(command)
        for pattern, naming, default in _DEFAULT_PORTS:
            words = shlex.split(command, comments=True)
            if pattern.match(command) and not any(w.split("=")[0] in naming for w in words):
                spelled = re.sub(r"\{(\d+)\}", lambda m: str(self.port(int(m.group(1)))), default)
                command = f"{pattern.match(command).group(0)} {spelled}{command[pattern.match(command).end() :]}"
        if self.steps is not None:
            command = re.sub(r"--steps[ =](\d+)", lambda m: f"--steps {min(int(m.group(1)), self.steps)}", command)
        if self.speedup is not None:
            command = re.sub(
                r"--speedup[ =]([\d.e+]+)", lambda m: f"--speedup {max(float(m.group(1)), self.speedup):g}", command
            )
        return re.sub(
            r"--duration[ =]([\d.]+)", lambda m: f"--duration {min(float(m.group(1)), self.duration):g}", command
        )

    # running --------------------------------------------------------------------------------------------------------
    def run(self, block: Block, background: bool | None = None) -> list[Step]:
        """Run a block's commands in order (see the module docstring). ``background=True`` starts every command
        in the background, as clients started while something else happens; the caller then waits for them."""
        self.blocks_run.append(block)
        if block.lang == "python":
            looping = "while True" in block.text
            script = self.logs / f"block-{Path(block.page).stem}-{block.line}.py"
            script.write_text(self.rewrite_ports(block.text))
            step = self._start(
                block,
                block.line,
                f"{shlex.quote(sys.executable)} {shlex.quote(str(script))}",
                looping if background is None else background,
            )
            return [step]
        skip = block.arg("skip")
        steps = []
        for line, command in block.commands():
            if skip and command.startswith(skip):
                continue
            command = self.rewrite(command)
            ampersand = shlex.split(command, comments=True)[-1] == "&"
            command = re.sub(r"\s*&\s*(#.*)?$", "", command) if ampersand else command
            bg = ampersand or bool(_LONG_LIVED.match(command))
            steps.append(self._start(block, line, command, bg if background is None else background))
        if skip:
            assert any(c.startswith(skip) for _l, c in block.commands()), (
                f"{block.where}: the marker skips '{skip}', which the block does not have"
            )
        return steps

    def again(self, step: Step) -> Step:
        """The same command once more (a second flight), to the end."""
        return self._start(step.block, step.line, step.command, False)

    def _start(self, block: Block, line: int, command: str, background: bool) -> Step:
        n = len(self.steps_run)
        out, err = self.logs / f"{n:02d}-L{line}.out", self.logs / f"{n:02d}-L{line}.err"
        lexer = shlex.shlex(command, posix=True, punctuation_chars=True)
        lexer.commenters = "#"
        simple = not {"&&", "||", ";", "|", "&"} & set(lexer)  # one command: bash execs it, so it gets the signals
        with open(out, "wb") as fo, open(err, "wb") as fe:
            proc = subprocess.Popen(
                ["bash", "-c", f"exec {command}" if simple else command],
                cwd=self.dir,
                env=self.env,
                stdin=subprocess.DEVNULL,
                stdout=fo,
                stderr=fe,
                start_new_session=True,
            )
        step = Step(block, line, command, proc, out, err, background)
        self.steps_run.append(step)
        if background:
            self._wait_ready(step)
        else:
            step.wait(self.timeout)
        return step

    def _wait_ready(self, step: Step) -> None:
        command = step.command
        if re.match(r"fault-monitor (run|router)\b", command):
            wait_for(lambda: "ready:" in step.err() or step.proc.poll() is not None, 30, what=step.where())
            assert "ready:" in step.err(), step.failure("exited before its ready line")
        elif command.startswith("mavproxy.py"):
            port = int(re.search(r"--master=udpin:[\d.]+:(\d+)", command).group(1))
            wait_for(lambda: udp_port_taken(port) or step.proc.poll() is not None, 30, what=step.where())
            assert step.proc.poll() is None, step.failure("exited at start")

    def stop(self) -> None:
        """Ctrl-C in every terminal still running, newest first; the project's daemons must then exit 0."""
        for step in reversed(self.steps_run):
            _end(step, signal.SIGINT, 15.0 if _OURS.match(step.command) else 3.0)
            step.returncode = step.proc.returncode
            if _OURS.match(step.command):
                assert step.returncode == 0, step.failure(f"exit code {step.returncode} after Ctrl-C")

    def assert_ran_all(self, name: str) -> None:
        missing = [b.where for b in group(name) if b not in self.blocks_run]
        assert not missing, f"blocks of group '{name}' at {missing} were not run by its test"


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _end(step: Step, first: int, grace: float) -> None:
    """Signal ``first`` to the step's whole process group and wait up to ``grace`` s for its command; then SIGTERM
    and SIGKILL whatever of the group is left. Nothing a command started outlives the session."""
    for sig, wait in ((first, grace), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        if step.proc.poll() is not None and not _group_alive(step.proc.pid):
            return
        try:
            os.killpg(step.proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            step.proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            pass
        deadline = time.monotonic() + (wait if step.proc.returncode is not None else 0)
        while _group_alive(step.proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)


def check_command_parses(command: str) -> str | None:
    """For a line that is not run: each fault-monitor or sim-vehicle command in it (``a && b`` is two) must parse
    with the real parser: its flags exist and their values have the right type. Returns the parser's complaint."""
    import contextlib
    import io

    from monitor.cli import build_parser as monitor_parser
    from sim_vehicle.cli import build_parser as vehicle_parser

    parsers = {"fault-monitor": monitor_parser, "sim-vehicle": vehicle_parser}
    words = shlex.split(command, comments=True)
    commands: list[list[str]] = [[]]
    for word in words:
        if word in ("&&", "||", ";", "|", "&"):
            commands.append([])
        elif not word.startswith(("<", ">")):
            commands[-1].append(word)
    for argv in commands:
        if not argv or argv[0] not in parsers:
            continue
        complaint = io.StringIO()
        try:
            with contextlib.redirect_stderr(complaint):
                parsers[argv[0]]().parse_args(argv[1:])
        except SystemExit as exc:
            if exc.code:
                return complaint.getvalue().strip().splitlines()[-1]
    return None
