"""Recovery from a local minimum: retreat to a ready posture when the tasks stall, then retry.

Both backends descend the task error locally (the pseudo-inverse, or a least squares over the
box, one step at a time). Towards a far target, and most of all from a singular start such as
the arms hanging straight, that descent can end where the joints pinned on their limits block
every direction that would reduce the error: a local minimum of the error over the joint
ranges, which no step of either backend leaves (``benchmarks/convergence.py``: from the neutral
posture, a third of random reachable targets end there, as they do for pink).

:class:`StallRecovery` watches the pose tasks' error ``E = sum_t ||e_t||`` (each ``e_t`` the
task's 6-D error, metres and radians added, 1 m counting as 1 rad). The reach **stalls** when,
over the last ``window`` seconds, every step left a watched task unmet (infeasible or scaled)
and ``E`` shrank by less than ``min(E / horizon, min_rate) window``: at that rate the error
would not shrink by a factor e within ``horizon`` seconds, nor by ``min_rate`` (m/s + rad/s) a
second. ``E`` below ``min_error`` never stalls, nor does ``E`` up to ``max_lag`` while a
watched task's reference moves (a target twist not 0): that error is a lag behind the
reference. A larger one means the hands lost it: under acceleration limits, from the arms
hanging straight, they can fall metres behind a minimum-jerk reference and end in a local
minimum when it stops; watched as for a target at rest, the reach retreats a second or more
earlier (``benchmarks/convergence.py``). The controller then **retreats**: it solves a
retreat stack (the levels above the watched tasks kept, e.g. a closed chain between the hands;
then a posture task towards the ready posture; the same constraints and metric) until every
posture joint is within ``tolerance`` of the ready posture (or ``max_retreat`` seconds
passed), zeroes the watched tasks' integrals and resumes.
At most ``max_retreats`` retreats per run. The ready posture defaults to the middle of every
limited joint's range, 0 for the others: the posture farthest from the limits that block, and
the one from which the same targets are reached most often (``benchmarks/README.md``,
"Convergence to random reachable targets").

Use it in a loop of your own in place of ``stack.advance``::

    recovery = StallRecovery(robot, stack)
    for k in range(n):
        state = robot.update(q)
        result = solver.solve(recovery.stack, state, dt)  # the stack to solve now
        recovery.advance(state, dt, result)               # advances it, watches, switches
        q = robot.integrate(q, result.u, dt)

A :class:`~wholebody.control.Controller` makes one by default (``recovery=True``) and
watches from its kernel's outcome (:meth:`StallRecovery.observe`); it logs the retreats.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from wholebody.errors import DimensionError, WholebodyError
from wholebody.robot import Robot, RobotState
from wholebody.solvers.result import SolverResult
from wholebody.solvers.stack import Level, Stack
from wholebody.tasks.base import Task
from wholebody.tasks.frame import FrameTask, PoseTask
from wholebody.tasks.posture import PostureTask

__all__ = ["Retreat", "StallRecovery", "mid_range_posture"]


def mid_range_posture(robot: Robot) -> np.ndarray:
    """Per actuated velocity, the middle of its position range where it has a finite one, 0
    elsewhere (wheels, endless joints, a planar base) (rad, m)."""
    lower, upper = robot.position_limits
    limited = np.isfinite(lower) & np.isfinite(upper)
    mid = np.zeros(robot.nu)
    mid[limited] = 0.5 * (lower[limited] + upper[limited])
    return mid


@dataclass
class Retreat:
    """One retreat: when it started and ended (s from the first :meth:`StallRecovery.advance`
    after the last :meth:`StallRecovery.reset`; ``end`` None while it lasts), and the watched
    error ``E`` when it started."""

    start: float
    end: float | None
    error: float


class StallRecovery:
    """Retreat to a ready posture when the watched tasks stall in a local minimum (module
    docstring).

    Parameters
    ----------
    robot, stack
        The robot and the stack that runs normally.
    tasks
        The tasks whose progress is watched (default: every :class:`FrameTask` of the stack).
    posture
        The ready posture: one position per actuated velocity (rad, m; base entries ignored),
        a mapping joint name -> position (others at :func:`mid_range_posture`), or ``"home"``;
        default :func:`mid_range_posture`.
    horizon
        The reach stalls when at its current rate the error would not shrink by a factor e
        within this time (s).
    window
        The time over which that rate is measured (s).
    min_error
        ``E`` below this (m + rad) never stalls.
    min_rate
        Nor does a reach whose ``E`` shrinks faster than this (m/s + rad/s), however large
        ``E``: far from the target the velocity limits, not a local minimum, set the pace.
    max_lag
        While a watched reference moves, an ``E`` up to this (m + rad) is a lag behind it,
        never a stall; beyond it the hands have lost the reference, and the reach is watched
        as for a target at rest (``inf``: a reach is never watched while a reference moves).
    gain
        The retreat's posture gain (1/s).
    tolerance
        The retreat ends when every posture joint is this close to the ready posture (rad, m).
    max_retreat
        The longest retreat (s).
    max_retreats
        Retreats per run at most.
    """

    def __init__(
        self,
        robot: Robot,
        stack: Stack,
        *,
        tasks: Sequence[Task] | None = None,
        posture: np.ndarray | Sequence[float] | Mapping[str, float] | str | None = None,
        horizon: float = 1.0,
        window: float = 0.15,
        min_error: float = 0.02,
        min_rate: float = 0.2,
        max_lag: float = 0.5,
        gain: float = 20.0,
        tolerance: float = 0.2,
        max_retreat: float = 2.0,
        max_retreats: int = 2,
    ) -> None:
        for name, value in (
            ("horizon", horizon),
            ("window", window),
            ("gain", gain),
            ("tolerance", tolerance),
            ("max_retreat", max_retreat),
            ("min_rate", min_rate),
        ):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise DimensionError(
                    f"StallRecovery: {name} must be a finite number > 0, got {value!r}"
                )
        if not (
            isinstance(min_error, (int, float)) and math.isfinite(min_error) and min_error >= 0
        ):
            raise DimensionError(
                f"StallRecovery: min_error must be finite and >= 0, got {min_error!r}"
            )
        if not (isinstance(max_lag, (int, float)) and max_lag > 0):  # (NaN compares false)
            raise DimensionError(
                f"StallRecovery: max_lag must be a number > 0 (inf: never "
                f"while a reference moves), got {max_lag!r}"
            )
        if not (isinstance(max_retreats, int) and max_retreats >= 0):
            raise DimensionError(
                f"StallRecovery: max_retreats must be an integer >= 0, got {max_retreats!r}"
            )
        self.robot, self.main = robot, stack
        self.watched = (
            list(tasks)
            if tasks is not None
            else [t for t in stack.tasks if isinstance(t, FrameTask)]
        )
        if not self.watched:
            raise WholebodyError(
                "StallRecovery: no task to watch (the stack has no FrameTask; "
                "name the tasks with tasks=)"
            )
        first = _first_level(stack, self.watched)
        self.ready = _ready_posture(robot, posture)
        joints = robot.actuated_joints[len(robot.base.actuators) :]
        self._joints = np.arange(len(robot.base.actuators), robot.nu)
        self.posture_task = PostureTask(
            robot, joints, name="retreat_posture", kp=gain, target=self.ready[self._joints]
        )
        self.retreat_stack = Stack(
            robot,
            [*stack.levels[:first], Level([self.posture_task], name="retreat")],
            stack.constraints,
            metric=stack.metric,
        )
        self.horizon, self.window, self.min_error = float(horizon), float(window), min_error
        self.min_rate, self.max_lag = float(min_rate), float(max_lag)
        self.tolerance, self.max_retreat, self.max_retreats = tolerance, max_retreat, max_retreats
        self._names = {t.name for t in self.watched}
        self._poses = [t for t in self.watched if isinstance(t, PoseTask)]
        self.reset()

    def reset(self) -> None:
        """Back to reaching, with no history and no retreat yet."""
        self.retreats: list[Retreat] = []
        """The retreats of this run."""
        self._time = 0.0
        self._history: deque[float] = deque()  # E over the last window, while unmet

    @property
    def retreating(self) -> bool:
        """Whether the retreat stack runs now."""
        return bool(self.retreats) and self.retreats[-1].end is None

    @property
    def stack(self) -> Stack:
        """The stack to solve at this step: the original one, or the retreat stack."""
        return self.retreat_stack if self.retreating else self.main

    def error(self, state: RobotState) -> float:
        """``E``: the sum of the watched tasks' error norms (m + rad)."""
        return float(sum(np.linalg.norm(t.error(state)) for t in self.watched))

    def advance(self, state: RobotState, dt: float, result: SolverResult) -> None:
        """After the step solved at ``state`` with ``result``: advance the stack that was
        solved (its integrators and constraints), then watch the reach or the retreat and
        switch between them (:meth:`observe`)."""
        self.stack.advance(state, dt, result=result)
        unmet = any(task in self._names for _, task in result.infeasible)
        error = self.error(state) if unmet and not self.retreating else 0.0
        self.observe(state.q, dt, unmet, self._moving(), error)

    def observe(self, q: np.ndarray, dt: float, unmet: bool, moving: bool, error: float) -> None:
        """Watch one step, solved at the configuration ``q``, whose stack has advanced
        already: ``unmet`` whether it left a watched task unmet, ``moving`` whether a watched
        reference moves, ``error`` the watched error ``E`` at ``q`` (read only when
        ``unmet``). Switches between the reach and the retreat."""
        self._time += dt
        if self.retreats and self.retreats[-1].end is None:
            self._watch_retreat(q)
        elif not unmet or (moving and error <= self.max_lag):
            self._history.clear()
        else:
            self._watch_reach(dt, error)

    def _watch_reach(self, dt: float, error: float) -> None:
        if error <= self.min_error:
            self._history.clear()
            return
        n = max(1, round(self.window / dt))
        self._history.append(error)
        while len(self._history) > n + 1:
            self._history.popleft()
        if len(self._history) <= n or len(self.retreats) >= self.max_retreats:
            return
        if self._history[0] - error < min(error / self.horizon, self.min_rate) * self.window:
            self.retreats.append(Retreat(self._time, None, error))
            self._history.clear()

    def _moving(self) -> bool:
        """Whether a watched pose task's reference moves (a target twist not 0)."""
        return any(t.target_twist.any() for t in self._poses)

    def _watch_retreat(self, q: np.ndarray) -> None:
        retreat = self.retreats[-1]
        gap = np.abs(self.robot.joint_positions(q)[self._joints] - self.ready[self._joints])
        wrapped = ~self.robot.positional[self._joints]
        gap[wrapped] = np.abs((gap[wrapped] + np.pi) % (2 * np.pi) - np.pi)
        if gap.max() <= self.tolerance or self._time - retreat.start >= self.max_retreat:
            retreat.end = self._time
            for task in self._poses:
                task.integral[:] = 0.0


def _first_level(stack: Stack, watched: Sequence[Task]) -> int:
    """The index of the first level holding a watched task, which must all be in the stack."""
    ids = {id(t) for t in watched}
    found = [k for k, level in enumerate(stack.levels) if ids & {id(t) for t in level.tasks}]
    inside = {id(t) for t in stack.tasks}
    missing = [t.name for t in watched if id(t) not in inside]
    if missing:
        raise WholebodyError(f"StallRecovery: tasks {missing} are not in the stack")
    return found[0]


def _ready_posture(
    robot: Robot,
    posture: np.ndarray | Sequence[float] | Mapping[str, float] | str | None,
) -> np.ndarray:
    """The ready posture as one position per actuated velocity."""
    mid = mid_range_posture(robot)
    if posture is None:
        return mid
    if isinstance(posture, str):
        if posture != "home":
            raise WholebodyError(
                f"StallRecovery: posture must be 'home', positions or a mapping, got {posture!r}"
            )
        return robot.joint_positions(robot.home())
    if isinstance(posture, Mapping):
        out = mid.copy()
        for name, value in posture.items():
            out[robot.index(name)] = float(value)
        return out
    out = np.asarray(posture, dtype=float)
    if out.shape != (robot.nu,) or not np.isfinite(out).all():
        raise DimensionError(
            f"StallRecovery: posture must be {robot.nu} finite positions "
            f"(one per actuated velocity), got shape {out.shape}"
        )
    return out.copy()
