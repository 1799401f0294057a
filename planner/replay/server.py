"""The replay served live: a meshcat server in a subprocess, on loopback unless asked.

The meshcat server has no authentication, so :func:`check_host` allows a non-loopback
address only with ``allow_remote``. Run as ``python -m planner.replay.server --serve``
(the subprocess body of :class:`ReplayServer`).
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from typing import TYPE_CHECKING

from planner.core.errors import InputError, PlannerError

if TYPE_CHECKING:
    from planner.replay.scene import Scene

__all__ = ["DEFAULT_HOST", "ReplayServer", "check_host", "check_port"]

DEFAULT_HOST = "127.0.0.1"


def check_host(host: str, allow_remote: bool = False) -> str:
    """The address to bind: ``host`` if it is loopback, or anything if ``allow_remote``.

    The meshcat server has no authentication: anyone who reaches it sees the scene, so it
    serves only this machine unless asked. ``localhost`` becomes ``127.0.0.1``.

    Raises
    ------
    InputError
        A non-loopback host without ``allow_remote``.

    """
    host = str(host).strip()
    if host == "localhost":
        return DEFAULT_HOST
    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if loopback or allow_remote:
        return host
    raise InputError(
        f"--host {host}: not a loopback address; the replay server has no authentication, "
        f"so it listens on {DEFAULT_HOST} only unless you also pass --allow-remote"
    )


def check_port(host: str, port: int | None) -> None:
    """InputError unless ``host`` can listen on ``port`` now.

    None is the first free port from 7000; else 1..65535, free, and allowed to this user.
    """
    if port is None:
        return
    if not 1 <= port <= 65535:
        raise InputError(f"--port {port}: expected 1..65535, or leave it out (the first free "
                         "port from 7000)")  # fmt: skip
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server does
            s.bind(address)
    except OSError as exc:
        raise InputError(
            f"--port {port}: cannot listen on {host}:{port} ({exc.strerror or exc}); choose "
            "another port, or leave --port out (the first free one from 7000)"
        ) from None


def _serve(host: str, port: int | None) -> None:
    """Run a meshcat server (subprocess body): web on ``host``, ZeroMQ on loopback only."""
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class Bridge(ZMQWebSocketBridge):
        def make_app(self):
            app = super().make_app()
            listen = app.listen

            def listen_on_host(p, **kw):
                self.http_server = listen(p, address=self.host, **kw)
                return self.http_server

            app.listen = listen_on_host
            return app

        def setup_zmq(self, url):
            return super().setup_zmq(re.sub(r"^tcp://.*:(\d+)$", r"tcp://127.0.0.1:\1", url))

    bridge = Bridge(host=host, port=port)
    shown = f"[{host}]" if ":" in host else host
    sockets = list(getattr(bridge.http_server, "_sockets", {}).values())
    real = sockets[0].getsockname()[1] if sockets else bridge.fileserver_port  # the bound one
    bridge.web_url = f"http://{shown}:{real}/static/"
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    bridge.run()


class ReplayServer:
    """A meshcat server in a subprocess, on loopback unless ``allow_remote``.

    Use as a context manager or call :meth:`start` / :meth:`stop`; :meth:`show` sends a
    :class:`Scene`. ``url`` is the page to open in a browser.
    """

    def __init__(
        self, host: str = DEFAULT_HOST, port: int | None = None, allow_remote: bool = False
    ):
        self.host = check_host(host, allow_remote)
        self.port = port
        self.proc: subprocess.Popen | None = None
        self.url = ""
        self.zmq_url = ""

    def start(self, timeout_s: float = 30.0) -> ReplayServer:
        """Start the server and wait for its URLs."""
        cmd = [sys.executable, "-u", "-m", "planner.replay.server", "--serve", "--host", self.host]
        if self.port is not None:
            cmd += ["--port", str(int(self.port))]
        self.proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
            start_new_session=True,
        )  # fmt: skip
        lines: list[str] = []

        def read() -> None:
            for line in self.proc.stdout:
                lines.append(line.strip())
                if line.startswith("web_url="):
                    return

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        reader.join(timeout_s)
        urls = dict(line.split("=", 1) for line in lines if "=" in line)
        if "web_url" not in urls or "zmq_url" not in urls:
            self.stop()
            raise PlannerError(
                f"replay: the meshcat server did not start on {self.host} within {timeout_s:g} s"
                f" (output: {' | '.join(lines)[:200]!r}); is the port free?"
            )
        self.url, self.zmq_url = urls["web_url"], urls["zmq_url"]
        return self

    def show(self, scene: Scene) -> None:
        """Send a recorded scene to the server (browsers connected now or later see it)."""
        scene.push(self.zmq_url)

    def stop(self) -> None:
        """Stop the server process (the one this object started)."""
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        if self.proc is not None and self.proc.stdout:
            self.proc.stdout.close()
        self.proc = None

    def __enter__(self) -> ReplayServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m planner.replay.server", description=__doc__)
    p.add_argument("--serve", action="store_true", required=True)
    p.add_argument("--host", default=DEFAULT_HOST)
    p.add_argument("--port", type=int, default=None)
    a = p.parse_args(argv)
    _serve(a.host, a.port)


if __name__ == "__main__":
    _main()
