"""Reference trajectories of one frame (a hand): the contract the controller consumes.

A :class:`Trajectory` maps time ``t`` (s, from the trajectory's start) to a
:class:`TrajectorySample`: position (m) and rotation in the world frame, linear velocity
(m/s), angular velocity (rad/s) and accelerations, all in world-aligned axes at the frame's
origin. Before ``t = 0`` it holds the start pose and after ``t = duration`` the end pose, with
zero velocity and acceleration in both cases.

Concrete trajectories here: :class:`MinimumJerkTrajectory` (quintic time scaling, slerp),
:class:`HoldTrajectory` (a constant pose) and :class:`TrajectorySequence` (concatenation).
:class:`~wholebody.planning.dmp.DMPTrajectory` and
:class:`~wholebody.planning.dual_arm.CoordinatedTrajectory` live beside the DMP and the
dual-arm chain.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody._numeric import count_nonzero as _count_nonzero
from wholebody.errors import WholebodyError
from wholebody.planning._checks import as_pose, as_positive, as_times
from wholebody.planning.rotations import Slerp

__all__ = [
    "HoldTrajectory",
    "MinimumJerkTrajectory",
    "Trajectory",
    "TrajectoryArrays",
    "TrajectoryError",
    "TrajectorySample",
    "TrajectorySequence",
    "minimum_jerk_scaling",
]

JOIN_TOL = 1e-6
"""Largest entry of ``|T_end(k) - T_start(k+1)|`` accepted where two segments join."""


class TrajectoryError(WholebodyError, ValueError):
    """Trajectories that cannot be combined (segments that do not join, empty sequences)."""


def _zeros3() -> np.ndarray:
    return np.zeros(3)


@dataclass(frozen=True)
class TrajectorySample:
    """The reference of one frame at one instant (world frame, world-aligned axes).

    Attributes
    ----------
    position
        Origin of the frame (3,), m.
    rotation
        Orientation (3, 3), frame axes in world coordinates.
    linear_velocity
        Velocity of the origin (3,), m/s.
    angular_velocity
        Angular velocity (3,), rad/s.
    linear_acceleration
        Acceleration of the origin (3,), m/s^2.
    angular_acceleration
        Angular acceleration (3,), rad/s^2 (zero unless the trajectory provides it).
    """

    position: np.ndarray
    rotation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    linear_acceleration: np.ndarray
    angular_acceleration: np.ndarray = field(default_factory=_zeros3)

    @property
    def pose(self) -> np.ndarray:
        """Homogeneous transform (4, 4) ``[[R, p], [0, 1]]``."""
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = self.position
        return T

    @property
    def twist(self) -> np.ndarray:
        """``[linear_velocity, angular_velocity]`` (6,), m/s and rad/s, world axes."""
        return np.concatenate([self.linear_velocity, self.angular_velocity])


@dataclass(frozen=True)
class TrajectoryArrays:
    """Samples of a trajectory at N instants, stacked along the first axis.

    Attributes
    ----------
    times
        (N,) s.
    positions, linear_velocities, angular_velocities, linear_accelerations,
    angular_accelerations
        (N, 3), in m, m/s, rad/s, m/s^2, rad/s^2, world axes.
    rotations
        (N, 3, 3).
    """

    times: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray
    linear_velocities: np.ndarray
    angular_velocities: np.ndarray
    linear_accelerations: np.ndarray
    angular_accelerations: np.ndarray

    def __len__(self) -> int:
        return int(self.times.shape[0])

    @property
    def poses(self) -> np.ndarray:
        """Homogeneous transforms (N, 4, 4)."""
        T = np.zeros((len(self), 4, 4))
        T[:, :3, :3] = self.rotations
        T[:, :3, 3] = self.positions
        T[:, 3, 3] = 1.0
        return T

    @property
    def twists(self) -> np.ndarray:
        """``[linear, angular]`` velocities (N, 6)."""
        return np.concatenate([self.linear_velocities, self.angular_velocities], axis=1)

    def at(self, index: int) -> TrajectorySample:
        """Sample ``index`` as a :class:`TrajectorySample` (copies)."""
        return TrajectorySample(
            position=self.positions[index].copy(),
            rotation=self.rotations[index].copy(),
            linear_velocity=self.linear_velocities[index].copy(),
            angular_velocity=self.angular_velocities[index].copy(),
            linear_acceleration=self.linear_accelerations[index].copy(),
            angular_acceleration=self.angular_accelerations[index].copy(),
        )


def constant_arrays(pose: np.ndarray, times: np.ndarray) -> TrajectoryArrays:
    """Arrays of a frame resting at ``pose`` (4x4) at every time of ``times`` (N,)."""
    n = times.shape[0]
    zeros = np.zeros((n, 3))
    return TrajectoryArrays(
        times=times,
        positions=np.tile(pose[:3, 3], (n, 1)),
        rotations=np.tile(pose[:3, :3], (n, 1, 1)),
        linear_velocities=zeros,
        angular_velocities=zeros.copy(),
        linear_accelerations=zeros.copy(),
        angular_accelerations=zeros.copy(),
    )


class Trajectory(abc.ABC):
    """A reference trajectory of one frame over ``[0, duration]`` seconds.

    Subclasses implement :attr:`duration` and :meth:`_evaluate` (times already inside
    ``[0, duration]``); this base class handles argument checks and the rest before the start
    and after the end. ``start_pose``/``end_pose`` default to the evaluation at 0 and at
    ``duration``.
    """

    @property
    @abc.abstractmethod
    def duration(self) -> float:
        """Length of the trajectory, s (> 0)."""

    @abc.abstractmethod
    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        """Samples at ``times`` (N,), every entry inside ``[0, duration]``; fresh arrays."""

    def sample_many(self, times: np.ndarray | Sequence[float]) -> TrajectoryArrays:
        """Samples at ``times`` (N,) s; outside ``[0, duration]`` the held end pose, at rest."""
        t = as_times(times, "times")
        T = self.duration
        out = self._evaluate(np.minimum(np.maximum(t, 0.0), T))
        outside = (t < 0.0) | (t > T)
        if _count_nonzero(outside):
            for arr in (
                out.linear_velocities,
                out.angular_velocities,
                out.linear_accelerations,
                out.angular_accelerations,
            ):
                arr[outside] = 0.0
        return TrajectoryArrays(
            times=t,
            positions=out.positions,
            rotations=out.rotations,
            linear_velocities=out.linear_velocities,
            angular_velocities=out.angular_velocities,
            linear_accelerations=out.linear_accelerations,
            angular_accelerations=out.angular_accelerations,
        )

    def sample(self, t: float) -> TrajectorySample:
        """The sample at time ``t`` (s from the start); see :meth:`sample_many`."""
        return self.sample_many(np.array([float(t)])).at(0)

    @property
    def start_pose(self) -> np.ndarray:
        """Pose at ``t = 0`` (4, 4)."""
        return self._evaluate(np.zeros(1)).poses[0]

    @property
    def end_pose(self) -> np.ndarray:
        """Pose at ``t = duration`` (4, 4)."""
        return self._evaluate(np.array([self.duration])).poses[0]


def minimum_jerk_scaling(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The quintic ``sigma(u) = 10 u^3 - 15 u^4 + 6 u^5`` and its first two derivatives.

    ``u`` in [0, 1] is normalised time; ``sigma`` rises from 0 to 1 with zero first and second
    derivatives at both ends (the minimum-jerk rest-to-rest profile).
    """
    u2 = u * u
    s = u2 * u * (10.0 + u * (-15.0 + 6.0 * u))
    ds = 30.0 * u2 * (1.0 + u * (-2.0 + u))
    dds = 60.0 * u * (1.0 + u * (-3.0 + 2.0 * u))
    return s, ds, dds


class MinimumJerkTrajectory(Trajectory):
    """Rest-to-rest motion between two poses with the minimum-jerk time scaling.

    With ``u = t / T`` and ``sigma(u)`` from :func:`minimum_jerk_scaling`:

    * position ``p(t) = p0 + sigma (p1 - p0)`` (straight line), velocity
      ``sigma' (p1 - p0) / T``, acceleration ``sigma'' (p1 - p0) / T^2``;
    * rotation ``R0 Exp(sigma Log(R0^T R1))`` (slerp, shortest way), angular velocity
      ``sigma' / T * R0 Log(R0^T R1)`` and acceleration ``sigma'' / T^2 * R0 Log(R0^T R1)``,
      exact.

    Parameters
    ----------
    start_pose, goal_pose
        4x4 world poses.
    duration
        ``T`` > 0, s.
    """

    def __init__(self, start_pose: np.ndarray, goal_pose: np.ndarray, duration: float) -> None:
        self._start = as_pose(start_pose, "MinimumJerkTrajectory: start_pose").copy()
        self._goal = as_pose(goal_pose, "MinimumJerkTrajectory: goal_pose").copy()
        self._duration = as_positive(duration, "MinimumJerkTrajectory: duration")
        self._slerp = Slerp(self._start[:3, :3], self._goal[:3, :3])

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def start_pose(self) -> np.ndarray:
        return self._start.copy()

    @property
    def end_pose(self) -> np.ndarray:
        return self._goal.copy()

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        T = self._duration
        s, ds, dds = minimum_jerk_scaling(times / T)
        dp = self._goal[:3, 3] - self._start[:3, 3]
        R, axis = self._slerp(s)
        return TrajectoryArrays(
            times=times,
            positions=self._start[:3, 3] + s[:, None] * dp,
            rotations=R,
            linear_velocities=(ds / T)[:, None] * dp,
            angular_velocities=(ds / T)[:, None] * axis,
            linear_accelerations=(dds / T**2)[:, None] * dp,
            angular_accelerations=(dds / T**2)[:, None] * axis,
        )


class HoldTrajectory(Trajectory):
    """A frame at rest at ``pose`` (4x4) for ``duration`` s."""

    def __init__(self, pose: np.ndarray, duration: float) -> None:
        self._pose = as_pose(pose, "HoldTrajectory: pose").copy()
        self._duration = as_positive(duration, "HoldTrajectory: duration")

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def start_pose(self) -> np.ndarray:
        return self._pose.copy()

    @property
    def end_pose(self) -> np.ndarray:
        return self._pose.copy()

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        return constant_arrays(self._pose, times)


class TrajectorySequence(Trajectory):
    """Segments played one after another: segment k starts when segment k-1 ends.

    The end pose of each segment must equal the start pose of the next (every entry to
    ``1e-6``); velocities may jump at a join unless the segments end and start at rest. At a
    join time the later segment is sampled.

    Parameters
    ----------
    segments
        One or more :class:`Trajectory` objects.
    """

    def __init__(self, segments: Sequence[Trajectory]) -> None:
        segs = tuple(segments)
        if not segs:
            raise TrajectoryError("TrajectorySequence: expected at least one segment, got none")
        for k, seg in enumerate(segs):
            if not isinstance(seg, Trajectory):
                raise TrajectoryError(
                    f"TrajectorySequence: segment {k} is a {type(seg).__name__}, "
                    "expected a Trajectory"
                )
        for k in range(len(segs) - 1):
            end, start = segs[k].end_pose, segs[k + 1].start_pose
            gap = float(np.max(np.abs(end - start)))
            if gap > JOIN_TOL:
                dp = float(np.linalg.norm(end[:3, 3] - start[:3, 3]))
                raise TrajectoryError(
                    f"TrajectorySequence: segment {k} ends at a pose that is not the start of "
                    f"segment {k + 1} (max entry difference {gap:.3g} > {JOIN_TOL:g}, position "
                    f"gap {dp:.3g} m); each segment must start where the previous one ends"
                )
        self.segments = segs
        durations = np.array([seg.duration for seg in segs])
        self._starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        self._durations = durations
        self._duration = float(np.sum(durations))

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def start_pose(self) -> np.ndarray:
        return self.segments[0].start_pose

    @property
    def end_pose(self) -> np.ndarray:
        return self.segments[-1].end_pose

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        index = np.searchsorted(self._starts[1:], times, side="right")
        k = int(index[0]) if index.size else 0
        if not _count_nonzero(index != k):  # one segment (a control step's samples): no copies
            local = np.minimum(np.maximum(times - self._starts[k], 0.0), self._durations[k])
            part = self.segments[k]._evaluate(local)
            return TrajectoryArrays(
                times,
                part.positions,
                part.rotations,
                part.linear_velocities,
                part.angular_velocities,
                part.linear_accelerations,
                part.angular_accelerations,
            )
        n = times.shape[0]
        P, V, W, A, B = (np.empty((n, 3)) for _ in range(5))
        R = np.empty((n, 3, 3))
        for k in np.unique(index):
            sel = index == k
            local = np.clip(times[sel] - self._starts[k], 0.0, self._durations[k])
            part = self.segments[k]._evaluate(local)
            P[sel], R[sel] = part.positions, part.rotations
            V[sel], W[sel] = part.linear_velocities, part.angular_velocities
            A[sel], B[sel] = part.linear_accelerations, part.angular_accelerations
        return TrajectoryArrays(times, P, R, V, W, A, B)
