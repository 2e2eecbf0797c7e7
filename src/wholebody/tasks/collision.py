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
from wholebody.kernels.collision import (
    CA_HEAD,
    CA_INFLUENCE,
    CA_SAFETY,
    CA_SPEED,
    CA_WITHIN,
    CA_WRITTEN,
    RESULT_WIDTH,
    SHAPE_WIDTH,
)
from wholebody.kernels.layout import KIND_COLLISION
from wholebody.robot import Robot, RobotState
from wholebody.tasks.base import InequalityRows, InequalityTask, Packed, Packer

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

    def __init__(
        self,
        robot: Robot,
        model: CollisionModel | None = None,
        *,
        obstacles: Sequence[Obstacle] = (),
        safety: float = 0.01,
        influence: float = 0.05,
        speed: float = 0.5,
        max_rows: int = 32,
        name: str = "collision",
    ) -> None:
        if not (math.isfinite(safety) and math.isfinite(influence) and 0 <= safety < influence):
            raise DimensionError(
                f"{name}: need 0 <= safety < influence (m), got {safety} and {influence}"
            )
        if not (math.isfinite(speed) and speed > 0) or int(max_rows) < 1:
            raise DimensionError(
                f"{name}: speed must be > 0 m/s and max_rows >= 1, got {speed} and {max_rows}"
            )
        self.name = name
        self.robot = robot
        self.model = model or CollisionModel(robot, obstacles, safety=safety)
        self.safety, self.influence, self.speed = float(safety), float(influence), float(speed)
        self.max_rows = int(max_rows)
        self._warned = False
        self._pairs: list[PairDistance] = []  # the rows' pairs of the last compute()
        self._params = np.zeros(0)  # the kernel's block (pack), when compiled

    @property
    def dim(self) -> int:
        return self.max_rows

    def bound(self, distance: float) -> float:
        """The smallest allowed ``d'`` (m/s) at ``distance`` (m) within the influence."""
        return -self.speed * (distance - self.safety) / (self.influence - self.safety)

    def check_step(self, dt: float) -> None:
        """A step of ``dt`` s must not cross the safety distance: ``speed dt <= influence -
        safety``, or DimensionError."""
        if self.speed * dt > self.influence - self.safety:
            raise DimensionError(
                f"{self.name}: speed * dt = {self.speed * dt:.3g} m exceeds "
                f"influence - safety = {self.influence - self.safety:.3g} m: "
                "a step could cross the safety distance"
            )

    def compute(self, state: RobotState, dt: float) -> InequalityRows:
        self.check_step(dt)
        near = self.model.distances(state, self.influence)  # closest first
        self._pairs = near[: self.max_rows]
        self._warn(len(near))
        if self._params.size:  # packed: the block reports the rows' pairs, as the kernel's
            self._record(near)
        C = np.zeros((self.max_rows, self.robot.nu))
        lower = np.full(self.max_rows, -np.inf)
        for r, pair in enumerate(self._pairs):
            C[r] = pair.row
            lower[r] = self.bound(pair.distance)
        return InequalityRows(C, lower, np.full(self.max_rows, np.inf))

    def _warn(self, within: int) -> None:
        """Once: more pairs within the influence than rows."""
        if within > self.max_rows and not self._warned:
            self._warned = True
            warnings.warn(
                f"{self.name}: {within} pairs within {self.influence} m but "
                f"max_rows = {self.max_rows}: the farthest {within - self.max_rows}"
                " have no row (raise max_rows)",
                stacklevel=3,
            )

    def _record(self, near: list[PairDistance]) -> None:
        """The rows' pairs into the block, as the kernel writes them."""
        par, m = self._params, self.max_rows
        written = min(len(near), m)
        par[CA_WRITTEN], par[CA_WITHIN] = written, len(near)
        index = {(self.model.pair_name(i, k)): p for p, (i, k) in enumerate(self.model.pairs)}
        at = CA_HEAD + m * RESULT_WIDTH
        for r in range(m):
            par[at + r] = index[near[r].name] if r < written else -1.0
            if r < written:
                pair = near[r]
                par[CA_HEAD + r * RESULT_WIDTH : CA_HEAD + (r + 1) * RESULT_WIDTH] = (
                    pair.distance,
                    *pair.point_a,
                    *pair.point_b,
                    *pair.normal,
                )

    @property
    def pairs(self) -> list[PairDistance]:
        """The pairs that got rows at the last evaluation, closest first (by :meth:`compute`,
        or by a stack's kernel)."""
        if not self._params.size:
            return self._pairs
        par, m = self._params, self.max_rows
        written = int(par[CA_WRITTEN])
        self._warn(int(par[CA_WITHIN]))
        found = par[CA_HEAD : CA_HEAD + m * RESULT_WIDTH].reshape(m, RESULT_WIDTH)
        index = par[CA_HEAD + m * RESULT_WIDTH :][:written].astype(int)
        out = []
        for r in range(written):
            i, k = self.model.pairs[index[r]]
            f = found[r].copy()
            name, a, b = self.model.pair_name(i, k), self.model.link(i), self.model.link(k)
            out.append(PairDistance(name, a, b, float(f[0]), f[1:4], f[4:7], f[7:10], None))
        return out

    def row_names(self) -> list[str]:
        """The pair of each row at the last evaluation (``""`` for an unused row)."""
        pairs = self.pairs
        return [p.name for p in pairs] + [""] * (self.max_rows - len(pairs))

    def pack(self, packer: Packer) -> Packed | None:
        """Compiled where every pair is one the kernel computes (no mesh)."""
        model = self.model
        packed = model.packed
        if (packed.pairs[:, 2] >= 0).any() or not self.compiled_as(CollisionAvoidance, "compute"):
            return None
        m, (S, _), P = self.max_rows, packed.shapes.shape, packed.pairs.shape[0]
        par = np.zeros(CA_HEAD + m * (RESULT_WIDTH + 1) + S * SHAPE_WIDTH)
        par[CA_SAFETY], par[CA_INFLUENCE], par[CA_SPEED] = self.safety, self.influence, self.speed
        par[CA_HEAD + m * (RESULT_WIDTH + 1) :] = packed.shapes.ravel()
        self._params = par
        ints = np.concatenate(
            [[S, P], packed.kinds.ravel(), packed.support.ravel(), packed.pairs.ravel()]
        ).astype(np.int64)
        return Packed(KIND_COLLISION, par, ints)

    def __repr__(self) -> str:
        return (
            f"CollisionAvoidance({self.name!r}, {len(self.model.pairs)} pairs, safety "
            f"{self.safety} m, influence {self.influence} m)"
        )
