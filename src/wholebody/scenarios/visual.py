"""Scenarios in MeshCat: objects, a live view paced at the control rate, and the replay."""

from __future__ import annotations

import time

import numpy as np

from wholebody.collision import CollisionModel, PairDistance
from wholebody.scenarios.runner import ScenarioRun
from wholebody.scenarios.spec import ScenarioSpec
from wholebody.viz.scene import Scene

__all__ = ["LiveView", "draw_objects", "show_run"]

HAND_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


def draw_objects(scene: Scene, spec: ScenarioSpec) -> None:
    """Every object of the scenario: obstacles in red, the rest in wood or grey."""
    for obj in spec.objects.values():
        color = (
            "#d62728"
            if obj.obstacle
            else ("#2ca02c" if obj.size[2] < 0.05 and obj.size[0] < 0.5 else "#b08d57")
        )
        if obj.kind == "box":
            scene.box(obj.name, obj.size, obj.pose, color=color)
        elif obj.kind == "cylinder":
            scene.cylinder(obj.name, obj.radius, obj.height, obj.pose, color=color)
        else:
            scene.ellipsoid(obj.name, [obj.radius] * 3, obj.pose, color=color)


def _draw_closest(scene: Scene, run: ScenarioRun) -> None:
    """The run's closest approach (its pair's witness points, from the metrics) as a line,
    and a marker between them."""
    m = run.metrics
    a, b = (np.asarray(p) for p in m["min_collision_points_m"])
    gap = b - a
    normal = gap / np.linalg.norm(gap) if np.linalg.norm(gap) > 0 else np.zeros(3)
    pair = PairDistance(
        m["min_collision_pair"], "", "", m["min_collision_distance_m"], a, b, normal, np.zeros(0)
    )
    scene.closest_pairs([pair], most=1, safety=run.spec.collision.safety)
    scene.marker("closest_approach", (a + b) / 2, color="#d62728", radius=0.01)


class LiveView:
    """A control-loop callback drawing the robot at most ``fps`` times a second and pacing
    the loop to real time (the control computation itself is much faster)."""

    def __init__(
        self,
        scene: Scene,
        dt: float,
        fps: float = 30.0,
        realtime: bool = True,
        collision: CollisionModel | None = None,
        influence: float = 0.05,
        safety: float = 0.01,
    ) -> None:
        self.scene, self.dt, self.realtime = scene, dt, realtime
        self.every = max(1, round(1.0 / (fps * dt)))
        self._start: float | None = None
        self.collision, self.influence, self.safety = collision, influence, safety
        """With a collision model, each drawn frame also shows the closest pairs within
        ``influence`` (m): :meth:`Scene.closest_pairs`."""
        self._objects: dict[str, np.ndarray] = {}

    def update_objects(self, poses: dict[str, np.ndarray]) -> None:
        """The objects' poses (a physics run's ``on_objects``), drawn with the next frame."""
        self._objects = poses

    def __call__(self, k: int, t: float, q: np.ndarray) -> None:
        if self._start is None:
            self._start = time.perf_counter() - t
        if k % self.every:
            return
        self.scene.show(q)
        for name, pose in self._objects.items():
            self.scene.move(f"scene/props/{name}", pose)
        if self.collision is not None:
            state = self.collision.robot.update(q)
            self.scene.closest_pairs(
                self.collision.distances(state, self.influence), safety=self.safety
            )
        if self.realtime:
            lag = (self._start + t) - time.perf_counter()
            if lag > 0:
                time.sleep(lag)


def show_run(scene: Scene, run: ScenarioRun, fps: float = 30.0) -> None:
    """Draw the executed and reference hand paths and replay the run as an animation."""
    log = run.log
    for i, name in enumerate(log.frame_positions):
        color = HAND_COLORS[i % len(HAND_COLORS)]
        pos, ref = log.frame_positions[name], log.reference_positions[name]
        pos, ref = pos[~np.isnan(pos).any(1)], ref[~np.isnan(ref).any(1)]
        if len(pos):
            scene.path(f"{name}_executed", pos, color=color)
            scene.path(f"{name}_reference", ref, color="#7f7f7f")
            scene.marker(f"{name}_goal", ref[-1], color=color)
    if run.metrics.get("min_collision_points_m") is not None:
        _draw_closest(scene, run)
    carried = {
        f"scene/props/{k}": v for k, v in run.object_poses.items() if not np.allclose(v[0], v[-1])
    }
    scene.animate(log.t, log.q, fps=fps, extra=carried)
