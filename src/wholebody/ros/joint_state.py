"""Measured joint positions and base pose to a configuration ``q``, each input checked.

A robot publishes its joints in one ``sensor_msgs/JointState`` or in several (one per
driver); :class:`StateAssembler` keeps each joint's newest position and when it arrived
(this host's monotonic clock, s), and the base pose from odometry. The state is usable when
every **required** joint (every positional joint of ``u``, and for a mobile base the base
pose) arrived within ``max_age`` seconds; its age is that of its oldest required part.
Wheels are optional: their angles move no frame a task reads (the base pose comes from
odometry), and many bases publish none.

A message is refused whole, and the positions already held kept, when one of its known
joints is not finite or lies more than ``tolerance`` (rad, m) outside the joint's limits:
a sensor fault makes the whole reading suspect. Positions within the tolerance are clipped
to the limits (encoders read a little past a hard stop). Joints the robot does not know
are ignored. A mimic joint is set from its leader, as ``q`` keeps it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wholebody.robot import Robot

__all__ = ["StateAssembler", "StateReading"]


@dataclass(frozen=True)
class StateReading:
    """The newest state: ``q`` (None when a required part never arrived), its age (s, of
    its oldest required part; ``inf`` when incomplete), the header stamp of the newest joint
    message (ns, the sender's clock), when that message arrived (s, this host's monotonic
    clock) and the required parts that never arrived."""

    q: np.ndarray | None
    age: float
    stamp: int
    arrived: float
    missing: tuple[str, ...] = ()


class StateAssembler:
    """Assembles ``q`` from joint-state and odometry messages (module docstring).

    Parameters
    ----------
    robot
        The robot whose ``q`` is assembled.
    tolerance
        How far (rad, m) outside its limits a joint position is still taken (clipped).
    """

    def __init__(self, robot: Robot, tolerance: float = 0.02) -> None:
        if not (math.isfinite(tolerance) and tolerance >= 0):
            raise ValueError(f"tolerance must be a finite number >= 0, got {tolerance!r}")
        self.robot, self.tolerance = robot, float(tolerance)
        model = robot.model
        lower, upper = robot.position_limits
        self._index: dict[str, tuple[int, bool, float, float]] = {}
        """name -> (q index, continuous, lower, upper)"""
        for k, name in enumerate(robot.actuated_joints):
            if not model.existJointName(name):
                continue  # a planar base's virtual actuator: its pose is odometry's
            joint = model.joints[model.getJointId(name)]
            self._index[name] = (joint.idx_q, joint.nq == 2, float(lower[k]), float(upper[k]))
        self._mimic = [
            (
                model.joints[model.getJointId(f)].idx_q,
                model.joints[model.getJointId(m.leader)].idx_q,
                m.multiplier,
                m.offset,
            )
            for f, m in robot.urdf.mimic.items()
            if model.existJointName(f) and model.existJointName(m.leader)
        ]
        """``(q index, leader's q index, multiplier, offset)`` of each mimic joint, which
        follows its leader (its own reading, if any, is not used)."""
        wheels = set(robot.base.wheel_joints)
        self.required: tuple[str, ...] = tuple(n for n in self._index if n not in wheels)
        """The joints every usable state has (the wheels are optional)."""
        self.mobile = robot.base.mobile
        self._q = robot.neutral()
        self._seen = {n: -math.inf for n in self.required}
        self._base_seen = -math.inf
        self._stamp = 0
        self._arrived = -math.inf

    @property
    def joints(self) -> tuple[str, ...]:
        """Every joint whose position is read (wheels included)."""
        return tuple(self._index)

    def update_joints(
        self, names: Sequence[str], positions: Sequence[float], now: float, stamp: int = 0
    ) -> str | None:
        """Take a joint-state message received at ``now`` (s, monotonic), ``stamp`` its
        header's time (ns); None when taken, else why it was refused (nothing kept)."""
        if len(names) != len(positions):
            return f"joint state has {len(names)} names but {len(positions)} positions"
        taken: list[tuple[str, float]] = []
        for name, value in zip(names, positions, strict=True):
            entry = self._index.get(name)
            if entry is None:
                continue
            value = float(value)
            _, continuous, lo, hi = entry
            if not math.isfinite(value):
                return f"joint state of {name} is not finite ({value})"
            if not continuous and not lo - self.tolerance <= value <= hi + self.tolerance:
                return (
                    f"joint state of {name} is {value:.4f}, outside its limits "
                    f"[{lo:.4f}, {hi:.4f}] by more than {self.tolerance} rad or m"
                )
            taken.append((name, value if continuous else min(max(value, lo), hi)))
        self._store(taken, now)
        if taken:
            self._stamp, self._arrived = int(stamp), now
        return None

    def _store(self, taken: list[tuple[str, float]], now: float) -> None:
        """Write checked positions into ``q`` and note when they arrived."""
        q = self._q
        for name, value in taken:
            iq, continuous, _, _ = self._index[name]
            if continuous:
                q[iq], q[iq + 1] = math.cos(value), math.sin(value)
            else:
                q[iq] = value
            if name in self._seen:
                self._seen[name] = now
        for i, leader, multiplier, offset in self._mimic:
            q[i] = multiplier * q[leader] + offset

    def update_base(self, x: float, y: float, yaw: float, now: float) -> str | None:
        """Take the base pose (m, m, rad; odometry frame) received at ``now``; None when
        taken, else why it was refused."""
        if not self.mobile:
            return None
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            return f"odometry is not finite: x {x}, y {y}, yaw {yaw}"
        self._q[0:4] = x, y, math.cos(yaw), math.sin(yaw)
        self._base_seen = now
        return None

    def reading(self, now: float) -> StateReading:
        """The newest state at ``now`` (a copy of ``q``; None until every required part
        arrived once)."""
        missing = tuple(n for n, t in self._seen.items() if t == -math.inf)
        oldest = min(self._seen.values(), default=now)
        if self.mobile:
            oldest = min(oldest, self._base_seen)
            if self._base_seen == -math.inf:
                missing += ("odometry",)
        if missing:
            return StateReading(None, math.inf, self._stamp, self._arrived, missing)
        return StateReading(self._q.copy(), now - oldest, self._stamp, self._arrived)
