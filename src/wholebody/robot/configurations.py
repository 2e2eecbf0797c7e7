"""Configurations ``q``: making them (neutral, home, by joint name, at random), checking them,
reading one position per actuated velocity from them, and moving along ``u``.

``q`` is Pinocchio's configuration vector (size ``nq``): a mobile base's planar root joint as
``(x, y, cos yaw, sin yaw)``, a floating base's free flyer as ``(x, y, z, qx, qy, qz, qw)`` (a
unit quaternion), a revolute or prismatic joint as its position, a continuous
joint (a wheel, an endless joint) as ``(cos, sin)`` of its angle. A mimic joint is always at
``multiplier q_leader + offset`` (every configuration made here keeps it there; ``u`` moves it
with its leader, :mod:`wholebody.robot.actuation`). Locked joints are not in ``q`` at all.

:meth:`~Configurations.joint_positions` reads ``q`` back as one scalar per entry of ``u``
(rad, m), the coordinates joint limits and posture tasks are written in; a floating base's
six as ``(x, y, z, roll, pitch, yaw)``.

A floating base **stands**: every configuration made here (neutral, home, by joint name, at
random) has the base upright (a random or given heading) at the height that puts the model's
lowest frame on the floor, z = 0 (:meth:`~Configurations.stand`); a humanoid's soles, for
example.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from wholebody._numeric import float_array
from wholebody.errors import DimensionError, FrameError
from wholebody.robot._names import suggest
from wholebody.robot.actuation import BASE, CONTINUOUS, SCALAR, Actuation
from wholebody.robot.base import BaseModel
from wholebody.robot.config import RobotConfig
from wholebody.robot.urdf import Mimic

if TYPE_CHECKING:
    from wholebody.robot.compiled import RobotKinematics

__all__ = ["Configurations"]

_FLOAT = np.dtype(float)


class Configurations:
    """The configuration helpers of :class:`~wholebody.robot.Robot` (one of its base
    classes; module docstring). :meth:`_init_configurations` lays out the index arrays from
    the actuation map once; the methods read them."""

    # set by Robot
    name: str
    config: RobotConfig
    model: pin.Model
    base: BaseModel
    nq: int
    nu: int
    actuation: np.ndarray
    position_limits: tuple[np.ndarray, np.ndarray]
    locked: Mapping[str, float]
    _u_index: dict[str, int]
    _joint_ids: dict[str, int]
    _followers: dict[str, Mimic]
    _home: np.ndarray
    kinematics: RobotKinematics

    def _init_configurations(self, act: Actuation) -> None:
        """Where each entry of ``u`` has its position in ``q``, and the neutral
        configuration."""
        kinds, qidx, lower, upper = act.kinds, act.q_index, act.lower, act.upper
        self._mimic_q = act.mimic
        self._q_shape = (self.model.nq,)
        self.positional: np.ndarray = kinds == SCALAR
        """Per actuated velocity: whether it has a bounded-or-not scalar joint position
        (revolute, prismatic); False for wheels and planar-base actuators."""
        self.positional.setflags(write=False)
        self._scalar = np.flatnonzero(kinds == SCALAR)
        self._scalar_q = qidx[self._scalar]
        self._cont = np.flatnonzero(kinds == CONTINUOUS)
        self._cont_q = qidx[self._cont]
        self._virtual = np.flatnonzero(kinds == BASE)
        # joint_positions()'s gathers: slices where the indices are runs (cheaper than fancy
        # indexing), the same entries
        self._scalar_ix = _as_slice(self._scalar)
        self._scalar_qix = _as_slice(self._scalar_q)
        self._cont_ix = _as_slice(self._cont)
        self._cont_cos = _as_slice(self._cont_q)
        self._cont_sin = _as_slice(self._cont_q + 1)
        # where q holds (cos, sin) pairs: the planar root's yaw, every continuous joint
        planar = self.base.mobile and not self.base.floating
        self._pairs = np.concatenate(([2] if planar else [], self._cont_q)).astype(int)
        self._pair_list: list[int] = self._pairs.tolist()
        self._stand_data = self.model.createData()
        # the zero configuration, every joint whose range excludes 0 at its nearer limit
        self._neutral = pin.neutral(self.model)
        self._neutral[self._scalar_q] = np.clip(0.0, lower[self._scalar], upper[self._scalar])
        self.stand(self._couple(self._neutral))
        self._neutral.setflags(write=False)

    def _couple(self, q: np.ndarray) -> np.ndarray:
        """``q`` with every mimic joint at ``multiplier q_leader + offset`` (in place)."""
        for i, leader, multiplier, offset in self._mimic_q:
            q[i] = multiplier * q[leader] + offset
        return q

    # ------------------------------------------------------------------ making them
    def neutral(self) -> np.ndarray:
        """The zero configuration: base at the world origin facing +x (a floating base above
        it, standing), all joints at 0 (a joint whose range excludes 0 at its nearer limit,
        so that it is a valid state)."""
        return self._neutral.copy()

    def home(self) -> np.ndarray:
        """The home posture of ``robot.toml`` (base at the origin; a floating base above it,
        standing)."""
        return self._home.copy()

    def configuration(
        self,
        joints: Mapping[str, float] | None = None,
        base_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> np.ndarray:
        """A configuration from joint values (rad, m) by name and a base pose (x, y, yaw; a
        floating base upright, standing)."""
        q = self._configuration_from(joints or {}, "joints")
        self._set_base(q, base_pose)
        return q

    def _configuration_from(self, joints: Mapping[str, float], where: str) -> np.ndarray:
        """The neutral configuration with ``joints`` (rad, m) by name, each checked: a
        ``robot.toml`` error for ``where == "home"``, else a :class:`FrameError` or
        :class:`DimensionError`."""
        q = self.neutral()
        for name, value in joints.items():
            msg, k = self._joint_value_error(name, value)
            if msg:
                if where == "home":
                    raise self.config.error(f"home.{name}", msg)
                if k < 0:
                    raise FrameError(msg)
                raise DimensionError(f"joint {name!r}: {msg}")
            j = self.model.joints[self._joint_ids[name]]
            if j.nq == 2:
                q[j.idx_q : j.idx_q + 2] = math.cos(value), math.sin(value)
            else:
                q[j.idx_q] = value
        return self.stand(self._couple(q))

    def stand(self, q: np.ndarray) -> np.ndarray:
        """For a floating base, ``q`` (in place) with the base raised or lowered so that the
        lowest frame of the model (every frame but the world's) is at z = 0: the robot stands
        on the floor with whatever is lowest. Other bases: ``q`` unchanged."""
        if not self.base.floating:
            return q
        pin.framesForwardKinematics(self.model, self._stand_data, q)
        low = min(
            M.translation[2]
            for M, f in zip(self._stand_data.oMf, self.model.frames, strict=True)
            if f.parentJoint > 0
        )
        q[2] -= low
        return q

    def _joint_value_error(self, name: str, value: object) -> tuple[str, int]:
        """``("", k)`` for a valid position of the actuated joint ``k``; else what is wrong,
        and ``k`` (-1 for a name that is no actuated joint)."""
        if name not in self._u_index:
            return _not_actuated(name, self.locked, self._followers, self._u_index), -1
        k = self._u_index[name]
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            return f"expected a number (rad or m), got {value!r}", k
        lower, upper = self.position_limits
        if not lower[k] <= value <= upper[k]:
            return f"{value} rad is outside the joint's limits [{lower[k]}, {upper[k]}]", k
        return "", k

    def _set_base(self, q: np.ndarray, pose: tuple[float, float, float]) -> None:
        """Write a base pose ``(x m, y m, yaw rad)`` into ``q`` (only zeros for a fixed base)."""
        if not self.base.mobile:
            if any(pose):
                raise DimensionError(
                    f"robot {self.name!r} has a fixed base: base_pose must be (0, 0, 0)"
                )
            return
        values = tuple(pose) if isinstance(pose, (tuple, list, np.ndarray)) else ()
        if len(values) != 3 or not all(
            isinstance(v, numbers.Real) and math.isfinite(v) for v in values
        ):
            raise DimensionError(
                f"base_pose must be three finite numbers (x m, y m, yaw rad), got {pose!r}"
            )
        x, y, yaw = map(float, values)
        if self.base.floating:  # upright, turned by yaw about z: the height is unchanged
            q[0:2] = x, y
            q[3:7] = 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)
            return
        q[0:4] = x, y, math.cos(yaw), math.sin(yaw)

    def random_configuration(
        self, rng: np.random.Generator, margin: float = 0.0, base_range: float = 1.0
    ) -> np.ndarray:
        """A configuration drawn uniformly inside the joint limits shrunk by ``margin``
        (fraction of each range on each side; a joint without a limit on one side within 2 pi
        (rad or m) of the other, without any in [-pi, pi]), wheels at random angles, base
        uniform in ``[-base_range, base_range]^2`` with any heading (a floating base upright,
        standing)."""
        if not (isinstance(margin, numbers.Real) and 0.0 <= margin < 0.5):
            raise DimensionError(
                "random_configuration: margin is the fraction of each range kept "
                f"clear on each side, in [0, 0.5); got {margin!r}"
            )
        if not (isinstance(base_range, numbers.Real) and 0.0 <= base_range < math.inf):
            raise DimensionError(
                f"random_configuration: base_range must be a finite distance "
                f">= 0 (m), got {base_range!r}"
            )
        lower, upper = self.position_limits
        q = self.neutral()
        s = self._scalar
        lo, hi = lower[s], upper[s]
        # a side without a limit: 2 pi (rad or m) from the other, or [-pi, pi] with neither
        has_lo, has_hi = np.isfinite(lo), np.isfinite(hi)
        lo, hi = (
            np.where(has_lo, lo, np.where(has_hi, hi - 2 * np.pi, -np.pi)),
            np.where(has_hi, hi, np.where(has_lo, lo + 2 * np.pi, np.pi)),
        )
        span = hi - lo
        q[self._scalar_q] = rng.uniform(lo + margin * span, hi - margin * span)
        ang = rng.uniform(-np.pi, np.pi, self._cont.size)
        q[self._cont_q], q[self._cont_q + 1] = np.cos(ang), np.sin(ang)
        if self.base.mobile:
            x, y = rng.uniform(-base_range, base_range, 2)
            self._set_base(q, (x, y, rng.uniform(-np.pi, np.pi)))
        return self.stand(self._couple(q))

    # ------------------------------------------------------------------ reading them
    def joint_positions(self, q: np.ndarray) -> np.ndarray:
        """One scalar position per entry of ``u`` (rad or m): joint angles, wheel angles in
        (-pi, pi], for a directly actuated planar base its pose (x, y, yaw), for a floating
        base its (x, y, z, roll, pitch, yaw) (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
        out = np.empty(self.nu)
        if self.base.floating:  # the compiled core's reading (roll, pitch, yaw)
            from wholebody.kernels.kinematics import joint_positions

            kin = self.kinematics
            joint_positions(q, kin.position_index, kin.position_pair, out)
            return out
        out[self._scalar_ix] = q[self._scalar_qix]
        out[self._cont_ix] = np.arctan2(q[self._cont_sin], q[self._cont_cos])
        if self._virtual.size:
            out[self._virtual] = self.base_pose(q)
        return out

    def base_pose(self, q: np.ndarray) -> np.ndarray:
        """Base pose ``(x [m], y [m], yaw [rad])`` in the world (zeros for a fixed base; a
        floating base's heading as in :meth:`joint_positions`)."""
        if not self.base.mobile:
            return np.zeros(3)
        if self.base.floating:
            return self.joint_positions(q)[[0, 1, 5]]
        return np.array([q[0], q[1], math.atan2(q[3], q[2])])

    # ------------------------------------------------------------------ checking them
    def check_configuration(self, q: np.ndarray) -> np.ndarray:
        """``q`` as a float array of shape (nq,), or a :class:`DimensionError`."""
        q = float_array(q, f"configuration of robot {self.name!r}")
        if q.shape != (self.nq,):
            raise DimensionError(
                f"configuration of robot {self.name!r} has shape {q.shape}; expected ({self.nq},)"
            )
        if not np.all(np.isfinite(q)):
            raise DimensionError(f"configuration of robot {self.name!r} is not finite: {q}")
        c, s = q[self._pairs], q[self._pairs + 1]
        bad = np.flatnonzero(np.abs(c * c + s * s - 1.0) > 1e-6)
        if bad.size:
            i = int(self._pairs[bad[0]])
            raise DimensionError(
                f"configuration of robot {self.name!r}: (q[{i}], q[{i + 1}]) = ({q[i]:g}, "
                f"{q[i + 1]:g}) is not a (cos, sin) pair: q stores the base's yaw and every "
                f"continuous joint's angle as cos and sin (nq = {self.nq} for nu = {self.nu}); "
                "build q with robot.neutral(), robot.home() or robot.configuration()"
            )
        if self.base.floating and abs(float(q[3:7].dot(q[3:7])) - 1.0) > 1e-6:
            raise DimensionError(
                f"configuration of robot {self.name!r}: q[3:7] = {q[3:7]} is not a unit "
                "quaternion (x, y, z, w): q stores the floating base's orientation so"
            )
        return q

    def _accept(self, q: np.ndarray) -> np.ndarray:
        """``q`` checked: the common case (a finite float vector of the right shape with unit
        (cos, sin) pairs) accepted fast, anything else through :meth:`check_configuration`.
        A NaN or inf makes ``q.q`` non-finite; an overflow of it only sends q to the full
        check."""
        if (
            q.__class__ is np.ndarray
            and q.dtype == _FLOAT
            and q.shape == self._q_shape
            and math.isfinite(q.dot(q))
            and self._unit_pairs(q)
        ):
            return q
        return self.check_configuration(q)

    def _unit_pairs(self, q: np.ndarray) -> bool:
        """Whether every (cos, sin) pair of ``q`` is a unit vector (to 1e-6), in scalar code:
        for the few pairs of a robot cheaper than :meth:`check_configuration`'s arrays."""
        for i in self._pair_list:
            c, s = q.item(i), q.item(i + 1)
            if abs(c * c + s * s - 1.0) > 1e-6:
                return False
        if self.base.floating:
            x, y, z, w = q.item(3), q.item(4), q.item(5), q.item(6)
            return abs(x * x + y * y + z * z + w * w - 1.0) <= 1e-6
        return True

    # ------------------------------------------------------------------ moving
    def integrate(self, q: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """Configuration reached from ``q`` by applying ``u`` for ``dt`` seconds (exact on
        the configuration manifold: the planar base follows the SE(2) exponential, a floating
        base SE(3)'s)."""
        q = self._accept(q)
        u = float_array(u, f"actuated velocity of robot {self.name!r}")
        if u.shape != (self.nu,):
            raise DimensionError(
                f"actuated velocity of robot {self.name!r} has shape "
                f"{u.shape}; expected ({self.nu},)"
            )
        if not math.isfinite(u.dot(u)):
            raise DimensionError(f"actuated velocity of robot {self.name!r} is not finite: {u}")
        if not (isinstance(dt, numbers.Real) and math.isfinite(dt)):
            raise DimensionError(f"integrate: dt must be a finite number of seconds, got {dt!r}")
        return pin.integrate(self.model, q, self.actuation.dot(u * dt))


def _not_actuated(
    name: str, locked: Mapping[str, float], followers: Mapping[str, Mimic], known: Mapping[str, int]
) -> str:
    """Why ``name`` cannot be given a position: locked, a mimic joint, or unknown."""
    if name in locked:
        return f"{name!r} is locked at {locked[name]:g} ([locked] of robot.toml)"
    if name in followers:
        return f"{name!r} is a mimic joint: give its leader {followers[name].leader!r}"
    return f"{name!r} is not a joint of the robot" + suggest(name, known)


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """``idx`` as an equivalent slice when it is an arithmetic run (step >= 1), else itself."""
    k = idx.tolist()
    if not k:
        return slice(0, 0)
    step = k[1] - k[0] if len(k) > 1 else 1
    if step >= 1 and k == list(range(k[0], k[-1] + 1, step)):
        return slice(k[0], k[-1] + 1, step)
    return idx
