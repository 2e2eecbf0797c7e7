"""The kinematics of a robot at one configuration: poses, Jacobians and centres of mass, each
computed once per state.

:meth:`Robot.update <wholebody.robot.Robot.update>` runs Pinocchio's forward kinematics and
joint Jacobians once and returns a :class:`RobotState`, a view of the robot's
``pinocchio.Data``; everything a task reads during one control step comes from it.

Poses are 4x4 homogeneous transforms in the world frame (z up). Frame Jacobians are 6 x nu
with world-aligned axes at the frame origin (Pinocchio's ``LOCAL_WORLD_ALIGNED``), linear
rows first, ``[v; w] = J u``, in actuated coordinates: Pinocchio's ``J_model`` (6 x nv) times
the actuation matrix ``A`` (:mod:`wholebody.robot.actuation`). The centre of mass of a body,
or of the whole robot (:mod:`wholebody.robot.com`), has a 3 x nu Jacobian in the same
coordinates.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
import pinocchio as pin

from wholebody.errors import WholebodyError
from wholebody.robot.com import center_of_mass
from wholebody.robot.parts import Body, Frame

if TYPE_CHECKING:
    from wholebody.robot.robot import Robot

__all__ = ["LWA", "WORLD", "RobotState"]

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
WORLD = pin.ReferenceFrame.WORLD
T = TypeVar("T")
_COM = ("com",)  # the cache key of the whole-body centre of mass (memo() keys are strings)


class RobotState:
    """Kinematics of a robot at one configuration (a view of the robot's Pinocchio data).

    Returned by :meth:`Robot.update`. Jacobians are computed once per frame and cached;
    the arrays returned are read-only views of that cache (fresh arrays per state: a
    Jacobian read from an older state keeps its values). The view is invalidated by the
    next :meth:`Robot.update`; using it afterwards raises :class:`WholebodyError`.

    :meth:`prefetch` (or :meth:`jacobians`) computes the Jacobians of many frames at once,
    with one product with the actuation matrix instead of one per frame; a
    :class:`~wholebody.solvers.Stack` prefetches the frames its entries declare before
    evaluating them.
    """

    __slots__ = ("_block", "_cache", "_order", "_rows", "_version", "q", "robot")

    def __init__(self, robot: Robot, q: np.ndarray, version: int) -> None:
        self.robot = robot
        self.q = q.copy()
        self.q.setflags(write=False)
        self._version = version
        self._cache: dict[object, Any] = {}
        self._block: np.ndarray | None = None  # the (F, 6, nu) Jacobians of prefetch()
        self._rows: dict[int, int] = {}  # frame index -> its first position in _block
        self._order: list[int] = []  # the frame index at each position of _block

    @property
    def stamp(self) -> float:
        """A number no other state of any robot has (what the kernels mark the rows they
        computed at this state with)."""
        return float(self._version)

    @property
    def valid(self) -> bool:
        """Whether this is the robot's newest state (a newer :meth:`Robot.update` makes it
        stale)."""
        return self._version == self.robot._version

    def require_valid(self) -> None:
        """Raise a :class:`WholebodyError` if this state is stale (a newer
        :meth:`Robot.update` was made): what a reader of the robot's shared kinematics checks
        first."""
        self._data()

    def _data(self) -> pin.Data:
        """The robot's Pinocchio data, or a :class:`WholebodyError` if this state is stale."""
        if self._version != self.robot._version:
            raise WholebodyError(
                "this RobotState is stale: Robot.update() was called again since it was "
                "made; keep using the newest state"
            )
        return self.robot.data

    def placement(self, frame: Frame) -> pin.SE3:
        """The frame's world placement as a ``pinocchio.SE3`` (a copy)."""
        return pin.SE3(self._data().oMf[frame.index])

    def pose(self, frame: Frame) -> np.ndarray:
        """4x4 world pose of ``frame``."""
        return self._data().oMf[frame.index].homogeneous

    def position(self, frame: Frame) -> np.ndarray:
        """World position (m) of the frame origin."""
        return self._data().oMf[frame.index].translation.copy()

    def rotation(self, frame: Frame) -> np.ndarray:
        """3x3 world orientation of the frame."""
        return self._data().oMf[frame.index].rotation.copy()

    def rotation_translation(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """The frame's world rotation (3x3) and position (3,) **without a copy**: views of the
        robot's data, overwritten by the next :meth:`Robot.update`; read, never write, them
        (for the control loop; :meth:`rotation` and :meth:`position` return copies)."""
        M = self._data().oMf[frame.index]
        return M.rotation, M.translation

    def jacobian(self, frame: Frame) -> np.ndarray:
        """6 x nu Jacobian (world-aligned axes at the frame origin, linear rows first)."""
        J = self._cache.get(frame.index)
        if J is None:
            k = self._rows.get(frame.index)
            if k is not None:  # in prefetch()'s block
                return self._block[k]
            robot = self.robot
            Jm = pin.getFrameJacobian(robot.model, self._data(), frame.index, LWA)
            J = Jm.dot(robot.actuation)
            J.setflags(write=False)
            self._cache[frame.index] = J
        return J

    def prefetch(self, frames: Sequence[Frame]) -> None:
        """Compute and cache the Jacobians of ``frames`` not cached yet, in one batch.

        The same numbers as :meth:`jacobian` frame by frame: Pinocchio's frame Jacobians
        stacked into one (6F x nv) array and multiplied by the actuation matrix once. On a
        fresh state the batch is kept as one (F, 6, nu) block in the order of ``frames``
        (repeats allowed), so that :meth:`jacobians` of a run of consecutive frames of it is
        a view, not a copy.
        """
        cache, rows = self._cache, self._rows
        missing = [f.index for f in frames if f.index not in cache and f.index not in rows]
        if not missing:
            return
        robot = self.robot
        model, data = robot.model, self._data()
        if len(missing) == 1:
            J = pin.getFrameJacobian(model, data, missing[0], LWA).dot(robot.actuation)
            J.setflags(write=False)
            cache[missing[0]] = J
            return
        get = pin.getFrameJacobian
        Jm = np.concatenate([get(model, data, i, LWA) for i in missing])
        J = Jm.dot(robot.actuation).reshape(len(missing), 6, robot.nu)
        J.setflags(write=False)
        if self._block is None:  # jacobian() reads the block (no per-frame cache entries)
            key = tuple(missing)
            rows = robot._layouts.get(key)
            if rows is None:  # first position of each frame, per layout (few per robot)
                rows = robot._layouts[key] = {i: k for k, i in reversed(list(enumerate(key)))}
            self._block, self._order, self._rows = J, missing, rows
            return
        for k, i in enumerate(missing):
            cache.setdefault(i, J[k])

    def jacobians(self, frames: Sequence[Frame]) -> np.ndarray:
        """(F, 6, nu) Jacobians of ``frames`` stacked (see :meth:`jacobian`), read-only.

        A view of :meth:`prefetch`'s block when the frames are consecutive in it; otherwise
        cached per tuple of frames, the frames not cached yet computed in one batch.
        """
        block = self._run(frames)
        if block is not None:
            return block
        key = ("stack", *(f.index for f in frames))
        block = self._cache.get(key)
        if block is None:
            self.prefetch(frames)
            block = self._run(frames)  # a fresh state: prefetch() made them one block
            if block is not None:
                return block
            block = np.stack([self.jacobian(f) for f in frames])
            block.setflags(write=False)
            self._cache[key] = block
        return block

    def _run(self, frames: Sequence[Frame]) -> np.ndarray | None:
        """The frames' Jacobians as a view of prefetch()'s block if they are consecutive
        in it, else None."""
        if self._block is None or not frames:
            return None
        ids = [f.index for f in frames]
        k0 = self._rows.get(ids[0], -1)
        if k0 >= 0 and self._order[k0 : k0 + len(ids)] == ids:
            return self._block[k0 : k0 + len(ids)]
        return None

    def world_jacobian(self, frame: Frame) -> np.ndarray:
        """6 x nv model Jacobian in Pinocchio's ``WORLD`` convention (spatial velocity at
        the world origin), model velocity columns (not actuated)."""
        key = ("world", frame.index)
        J = self._cache.get(key)
        if J is None:
            J = pin.getFrameJacobian(self.robot.model, self._data(), frame.index, WORLD)
            J.setflags(write=False)
            self._cache[key] = J
        return J

    def com_position(self, body: Body | None = None) -> np.ndarray:
        """World position (m) of the body's centre of mass; without a body, of the whole
        robot's (every link's mass, locked and fixed ones included: :mod:`~.com`; computed
        once per state with its Jacobian, read-only)."""
        if body is None:
            return self._com()[0]
        M = self._data().oMf[body.frame.index]
        return M.translation + M.rotation @ body.com

    def com_jacobian(self, body: Body | None = None) -> np.ndarray:
        """3 x nu Jacobian of the body's centre of mass (world axes); without a body, of the
        whole robot's (read-only, cached like :meth:`com_position`)."""
        if body is None:
            return self._com()[1]
        J = self.jacobian(body.frame)
        rx, ry, rz = self._data().oMf[body.frame.index].rotation @ body.com
        # v_com = v_o + w x r = v_o - [r]x w
        return J[:3] - np.array([[0.0, -rz, ry], [rz, 0.0, -rx], [-ry, rx, 0.0]]) @ J[3:]

    def _com(self) -> tuple[np.ndarray, np.ndarray]:
        """The whole-body centre of mass and its Jacobian, computed on first use."""
        com = self._cache.get(_COM)
        if com is None:
            robot = self.robot
            com = center_of_mass(robot.model, self._data(), robot.actuation)
            self._cache[_COM] = com
        return com

    def memo(self, key: str, compute: Callable[[RobotState], T]) -> T:
        """``compute(self)``, computed once per state and cached under ``key`` (for values
        that several tasks derive from the same state; ``key`` must name what ``compute``
        returns, and the result must not be modified)."""
        value = self._cache.get(key)
        if value is None:
            value = self._cache[key] = compute(self)
        return value

    def joint_positions(self) -> np.ndarray:
        """Scalar position per actuated velocity (see :meth:`Robot.joint_positions`)."""
        jp = self._cache.get("joint_positions")
        if jp is None:
            jp = self.robot.joint_positions(self.q)
            jp.setflags(write=False)
            self._cache["joint_positions"] = jp
        return jp
