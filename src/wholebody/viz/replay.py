"""A run shown in MeshCat in one call: what a script's ``--viz`` does.

:func:`replay` draws the robot, lets the caller add props and markers, replays the run
(configurations at their times) as a MeshCat animation, saves it as one standalone page and
then, on a terminal, keeps the localhost-only viewer open until Enter; without a terminal the
server is closed and the page remains.
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wholebody.errors import DimensionError
from wholebody.robot import Robot
from wholebody.viz.scene import Scene

__all__ = ["replay"]


def replay(
    robot: Robot,
    times: np.ndarray,
    qs: np.ndarray,
    *,
    draw: Callable[[Scene], None] | None = None,
    extra: dict[str, np.ndarray] | None = None,
    page: str | Path | None = None,
    hold: bool | None = None,
) -> Path:
    """Replay configurations ``qs`` (N, nq) at ``times`` (N,) s in a new :class:`Scene`.

    ``draw(scene)`` adds props, markers and paths before the replay; ``extra`` maps the scene
    paths of props so drawn (``"scene/props/NAME"``) to their (N, 4, 4) poses, animated
    alongside the robot (a carried object). The replay is saved to
    ``page`` (default: ``replay.html`` in a new temporary directory), which opens in a
    browser without a server. ``hold``: wait for Enter with the viewer open (default: when
    standard input is a terminal). The server (bound to 127.0.0.1) is stopped before
    returning. Returns the page's path."""
    times = np.asarray(times, dtype=float)
    qs = np.asarray(qs, dtype=float)
    if times.ndim != 1 or qs.shape != (times.size, robot.nq) or times.size == 0:
        raise DimensionError(
            f"replay needs N times and N x {robot.nq} configurations of robot "
            f"{robot.name!r}, got shapes {times.shape} and {qs.shape}"
        )
    if not (np.isfinite(times).all() and np.isfinite(qs).all()):
        raise DimensionError("replay: times and configurations must be finite")
    if page is None:
        page = Path(tempfile.mkdtemp(prefix="wholebody-replay-")) / "replay.html"
    scene = Scene(robot)
    try:
        if draw is not None:
            draw(scene)
        scene.show(qs[0])
        scene.animate(times - times[0], qs, extra=extra)
        path = scene.save_html(page)
        print(f"replay: {path} (a standalone page: open it in a browser)")
        if sys.stdin.isatty() if hold is None else hold:
            print(f"MeshCat at {scene.url} (its Animations controls replay the run); press Enter")
            try:
                input()
            except (EOFError, KeyboardInterrupt):
                print()
    finally:
        scene.close()
    return path
