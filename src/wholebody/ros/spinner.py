"""A node's callbacks served on a thread of their own, for the two nodes of this package.

The control loop (or the simulated robot's) runs on the main thread at its rate; the
messages arrive on another, an events executor spun in waits of ``WAIT`` s, so that
:meth:`Spinner.close` stops it within that time.
"""

from __future__ import annotations

import threading

from rclpy.experimental import EventsExecutor
from rclpy.node import Node

__all__ = ["WAIT", "Spinner"]

WAIT = 0.05
"""The executor's longest wait for a message (s): how long :meth:`Spinner.close` may take
to stop it."""


class Spinner:
    """The executor thread of ``node``: :meth:`start` it, then :meth:`close` it (which
    destroys the node too)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.executor = EventsExecutor()
        self.executor.add_node(node)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True, name="ros-executor")

    def start(self) -> None:
        """Serve the node's callbacks from now on."""
        self._thread.start()

    def _spin(self) -> None:
        while not self._closing.is_set():
            self.executor.spin_once(timeout_sec=WAIT)

    def close(self) -> None:
        """Stop the executor thread (it ends within ``WAIT``), then the node."""
        self._closing.set()
        if self._thread.is_alive():
            self._thread.join()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
