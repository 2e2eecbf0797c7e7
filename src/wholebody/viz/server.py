"""A MeshCat server that listens on localhost only.

meshcat-python's bridge binds its ZeroMQ socket to 127.0.0.1, but its Tornado web server
(the page and the websocket a browser connects to) listens on every interface. This module
runs the same bridge with a web application that always listens on 127.0.0.1, so the
viewer is never exposed to the network. Run it with ``python -m wholebody.viz.server``; it
prints ``zmq_url=...`` and ``web_url=...`` like ``meshcat-server``.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import subprocess
import sys
from dataclasses import dataclass

import tornado.web
from meshcat.servers.zmqserver import (
    VIEWER_HTML,
    VIEWER_ROOT,
    StaticFileHandlerNoCache,
    WebSocketHandler,
    ZMQWebSocketBridge,
    match_web_url,
    match_zmq_url,
)

from wholebody.errors import WholebodyError

__all__ = ["LOCALHOST", "LocalServer", "start_server"]

LOCALHOST = "127.0.0.1"


class _LocalhostApplication(tornado.web.Application):
    """A Tornado application whose ``listen`` binds 127.0.0.1 whatever it is asked."""

    def listen(self, port: int, address: str | None = None, **kwargs):
        return super().listen(port, address=LOCALHOST, **kwargs)


class LocalhostBridge(ZMQWebSocketBridge):
    """meshcat's ZeroMQ-to-websocket bridge with its web server on localhost only."""

    def __init__(self, zmq_url: str | None = None) -> None:
        super().__init__(zmq_url=zmq_url, host=LOCALHOST)

    def make_app(self) -> tornado.web.Application:
        return _LocalhostApplication(
            [
                (
                    r"/static/(.*)",
                    StaticFileHandlerNoCache,
                    {"path": VIEWER_ROOT, "default_filename": VIEWER_HTML},
                ),
                (r"/", WebSocketHandler, {"bridge": self}),
            ]
        )


@dataclass
class LocalServer:
    """A running localhost MeshCat server (a child process)."""

    process: subprocess.Popen
    zmq_url: str
    web_url: str

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


def start_server(timeout: float = 20.0) -> LocalServer:
    """Start ``python -m wholebody.viz.server`` and return its URLs (it stops at exit)."""
    proc = subprocess.Popen(
        [sys.executable, "-u", "-m", "wholebody.viz.server"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=dict(os.environ),
        start_new_session=True,
    )
    lines = []
    while True:
        line = proc.stdout.readline().decode("utf-8").strip()
        if not line and proc.poll() is not None:
            err = proc.stderr.read().decode("utf-8")
            raise WholebodyError(f"the MeshCat server exited early ({proc.returncode}): {err}")
        lines.append(line)
        if line.startswith("web_url="):
            break
    zmq_url = match_zmq_url(next(x for x in lines if x.startswith("zmq_url=")))
    server = LocalServer(proc, zmq_url, match_web_url(lines[-1]))
    atexit.register(server.stop)
    return server


def main() -> None:
    bridge = LocalhostBridge()
    print(f"zmq_url={bridge.zmq_url}")
    print(f"web_url={bridge.web_url}")
    with contextlib.suppress(KeyboardInterrupt):
        bridge.run()


if __name__ == "__main__":
    main()
