"""Fixtures: the app in-process (TestClient, lifespan run) and a real uvicorn server on loopback."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.config import Settings

ROOT = Path(__file__).resolve().parents[2]
#: Bound on every wait in these tests (a hang fails instead of blocking the suite); never asserted as a speed.
WAIT_S = 120.0


def long_line(length_mm: float = 10_000.0, knot_spacing: float = 1.0) -> dict[str, Any]:
    """A straight line that takes seconds to schedule (many LP windows, progress after each)."""
    return {
        "toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1],
                                   "control_points": [[0, 0, 0], [length_mm, 0, 0]]}]},
        "machine": "router",
        "options": {"knot_spacing": knot_spacing},
    }


def wait_for(pred: Callable[[], Any], what: str, timeout: float = WAIT_S, every: float = 0.05) -> Any:
    deadline = time.monotonic() + timeout
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > deadline:
            raise AssertionError(f"gave up waiting for {what}")
        time.sleep(every)


def pid_gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    try:  # a zombie is gone for our purposes (it runs no code)
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] == "Z"
    except OSError:
        return True


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("data"), workers=2, max_body_bytes=200_000,
                              sync_max_control_points=500, sync_max_samples=50_000))
    with TestClient(app, raise_server_exceptions=False) as c:
        yield c


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """uvicorn serving ``app`` (default service.app:app) in a subprocess on 127.0.0.1."""

    def __init__(self, data_dir: Path, app: str = "service.app:app", **env: str) -> None:
        self.app = app
        self.data_dir = data_dir
        self.env = {**os.environ, "FEEDSCHED_DATA_DIR": str(data_dir), **env}
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen[bytes] | None = None
        self.log = data_dir / "server.log"

    def start(self) -> Server:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "uvicorn", self.app, "--host", "127.0.0.1", "--port", str(self.port)],
                cwd=ROOT, env=self.env, stdout=log, stderr=subprocess.STDOUT,
            )

        def up() -> bool:
            assert self.proc is not None and self.proc.poll() is None, self.log.read_text()[-3000:]
            try:
                return httpx.get(self.url + "/healthz", timeout=1.0).status_code == 200
            except httpx.HTTPError:
                return False

        wait_for(up, "uvicorn to answer /healthz", every=0.1)
        return self

    def kill(self) -> None:
        """Hard stop (SIGKILL): no shutdown code runs."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=WAIT_S)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.kill()


@pytest.fixture
def server_factory(tmp_path: Path) -> Iterator[Callable[..., Server]]:
    servers: list[Server] = []

    def make(**env: str) -> Server:
        s = Server(tmp_path, **env)
        servers.append(s)
        return s

    yield make
    for s in servers:
        s.stop()


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    s = Server(tmp_path_factory.mktemp("srv"), FEEDSCHED_WORKERS="2").start()
    yield s
    s.stop()
