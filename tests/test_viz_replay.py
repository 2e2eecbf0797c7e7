"""``wholebody.viz.replay``: a run replayed and saved as a page in one call."""

from __future__ import annotations

import numpy as np
import pytest

import wholebody as wb
from wholebody.viz import replay


def test_replay_saves_a_standalone_page_and_closes_its_server(tmp_path, capsys, monkeypatch):
    robot = wb.load_robot("dual_arm_torso")
    q0 = robot.home()
    qs = np.array([q0, robot.integrate(q0, np.full(robot.nu, 0.5), 1.0)])
    servers = []
    original = wb.viz.Scene.close

    def close(scene):
        servers.append(scene.server)
        original(scene)

    monkeypatch.setattr(wb.viz.Scene, "close", close)
    marker = lambda scene: scene.marker("goal", (0.5, 0.0, 1.0))  # noqa: E731
    page = replay(
        robot, np.array([0.0, 1.0]), qs, page=tmp_path / "r.html", hold=False, draw=marker
    )
    text = page.read_text()
    assert page == tmp_path / "r.html" and "<html" in text.lower()
    assert len(text) > 10_000, "the page should hold the robot's meshes and the replay"
    assert str(page) in capsys.readouterr().out
    assert len(servers) == 1 and servers[0] is not None
    assert servers[0].process.poll() is not None, "the server should be stopped"


def test_replay_refuses_mismatched_shapes():
    robot = wb.load_robot("dual_arm_torso")
    with pytest.raises(wb.DimensionError, match="configurations"):
        replay(robot, np.zeros(3), np.zeros((2, robot.nq)), hold=False)
