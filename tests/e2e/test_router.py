"""``fault-monitor router``: two clients that know only the router exchange a sample; bad endpoints are one line."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

from tests.daemons import Daemon, free_tcp_port, wait_for


def test_clients_of_the_router_see_each_other(tmp_path: Path) -> None:
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with Daemon("monitor", ["router", "-l", endpoint], tmp_path / "router.log") as router:
        wait_for(lambda: "ready:" in router.log(), 20, what="router ready")
        assert endpoint in router.log()
        sub = open_session(build_config(connect=[endpoint], mode="client"))
        pub = open_session(build_config(connect=[endpoint], mode="client"))
        got: list[dict] = []
        lock = threading.Lock()

        def on_sample(sample) -> None:
            with lock:
                got.append(json.loads(sample.payload.to_bytes()))

        subscriber = sub.declare_subscriber("uav/*/fault/estimate", on_sample)
        try:

            def published() -> bool:
                pub.put("uav/7/fault/estimate", json.dumps({"sysid": 7, "k": 1}))
                return bool(got)

            wait_for(published, 10, interval=0.2, what="a sample through the router")
        finally:
            close_quietly(sub, subscriber)
            close_quietly(pub)
        assert got[0] == {"sysid": 7, "k": 1}
        assert router.stop() == 0


def test_an_invalid_endpoint_is_one_line_exit_2() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "monitor", "router", "-l", "tcp/256.1.1.1:7447"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "not a valid IP address" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and ".rs:" not in out.stderr
