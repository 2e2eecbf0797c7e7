"""Collision avoidance as inequality rows: the velocity damper of Faverjon and Tournassoud.

For every checked pair (:class:`wholebody.collision.CollisionModel`) closer than the
influence distance ``d_i``, one row bounds how fast the pair may approach::

    d'(u) = n^T (J_b(p_b) - J_a(p_a)) u  >=  -xi (d - d_s) / (d_i - d_s)

``d`` the pair's distance (m), ``d_s`` the safety distance (m), ``xi`` the approach speed (m/s)
allowed at ``d_i``, decreasing linearly to 0 at ``d_s``; below ``d_s`` the bound is positive
and the pair is pushed apart. In continuous time ``d`` never falls below ``d_s``; a control
step of ``dt`` keeps that when ``xi dt <= d_i - d_s`` (checked). A pair farther than ``d_i``
has no row.

The rows are hard in the HQP at the level that holds them (put the task in the first level:
every level below is solved inside them); the projection backend enforces them above every
level (:class:`~wholebody.solvers.ProjectionSolver`). ``dim`` is ``max_rows``: the closest
pairs get the rows, the rest are ``-inf`` (inactive).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from wholebody.collision import CollisionModel, Obstacle, PairDistance
from wholebody.errors import DimensionError
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import InequalityRows, InequalityTask

__all__ = ["CollisionAvoidance"]


class CollisionAvoidance(InequalityTask):
    """Keep every checked pair at least ``safety`` apart (module docstring).

    Parameters
    ----------
    robot
        The robot.
    model
        The shapes and pairs (default: the robot's own, with ``obstacles``).
    obstacles
        Shapes fixed in the world, when ``model`` is not given.
    safety, influence
        ``d_s < d_i`` (m).
    speed
        ``xi`` (m/s): the approach speed allowed at ``d_i``.
    max_rows
        Rows reserved: the closest pairs within ``d_i`` get them (a warning, once, when
        more pairs are that close).
    """

    def __init__(self, robot: Robot, model: CollisionModel | None = None, *,
                 obstacles: Sequence[Obstacle] = (), safety: float = 0.01,
                 influence: float = 0.05, speed: float = 0.5, max_rows: int = 32,
                 name: str = "collision") -> None:  # fmt: skip
        if not (math.isfinite(safety) and math.isfinite(influence) and 0 <= safety < influence):
            raise DimensionError(f"{name}: need 0 <= safety < influence (m), got {safety} and "
                                 f"{influence}")  # fmt: skip
        if not (math.isfinite(speed) and speed > 0) or int(max_rows) < 1:
            raise DimensionError(f"{name}: speed must be > 0 m/s and max_rows >= 1, got {speed} "
                                 f"and {max_rows}")  # fmt: skip
        self.name = name
        self.robot = robot
        self.model = model or CollisionModel(robot, obstacles, safety=safety)
        self.safety, self.influence, self.speed = float(safety), float(influence), float(speed)
        self.max_rows = int(max_rows)
        self._warned = False
        self.pairs: list[PairDistance] = []
        """The pairs that got rows at the last :meth:`compute`, closest first."""

    @property
    def dim(self) -> int:
        return self.max_rows

    def bound(self, distance: float) -> float:
        """The smallest allowed ``d'`` (m/s) at ``distance`` (m) within the influence."""
        return -self.speed * (distance - self.safety) / (self.influence - self.safety)

    def compute(self, state: RobotState, dt: float) -> InequalityRows:
        if self.speed * dt > self.influence - self.safety:
            raise DimensionError(f"{self.name}: speed * dt = {self.speed * dt:.3g} m exceeds "
                                 f"influence - safety = {self.influence - self.safety:.3g} m: "
                                 "a step could cross the safety distance")  # fmt: skip
        near = sorted(self.model.distances(state, self.influence), key=lambda p: p.distance)
        self.pairs = near[: self.max_rows]
        if len(near) > self.max_rows and not self._warned:
            self._warned = True
            warnings.warn(f"{self.name}: {len(near)} pairs within {self.influence} m but "
                          f"max_rows = {self.max_rows}: the farthest {len(near) - self.max_rows}"
                          " have no row (raise max_rows)", stacklevel=2)  # fmt: skip
        C = np.zeros((self.max_rows, self.robot.nu))
        lower = np.full(self.max_rows, -np.inf)
        for r, pair in enumerate(self.pairs):
            C[r] = pair.row
            lower[r] = self.bound(pair.distance)
        return InequalityRows(C, lower, np.full(self.max_rows, np.inf))

    def row_names(self) -> list[str]:
        """The pair of each row at the last :meth:`compute` (``""`` for an unused row)."""
        return [p.name for p in self.pairs] + [""] * (self.max_rows - len(self.pairs))

    def __repr__(self) -> str:
        return (f"CollisionAvoidance({self.name!r}, {len(self.model.pairs)} pairs, safety "
                f"{self.safety} m, influence {self.influence} m)")  # fmt: skip
