"""What the compiled core reads from a robot: Pinocchio's data through views, the actuation
matrix's entries, frame supports and joint-position indices.

After :meth:`Robot.update <wholebody.Robot.update>` (``computeJointJacobians`` and
``updateFramePlacements``) the joint Jacobians ``data.J`` (6 x nv) and the frame placements
``data.oMf`` hold everything the kernels need. Reading them through the Python proxies costs
microseconds per frame; :meth:`RobotKinematics.views` instead returns numpy views of that
memory, made once: ``data.J`` itself (column-major) and the placements as an (nframes, 12)
array, each row a rotation in column-major order followed by the translation (the memory
layout of Pinocchio's ``SE3``). The layout is checked against the proxies when the views are
made; where it is not the one assumed (another Pinocchio build), the placements are gathered
through the proxies instead: slower, never wrong.
"""

from __future__ import annotations

import ctypes
import functools
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from wholebody.errors import ModelError

if TYPE_CHECKING:
    from wholebody.robot.parts import Frame
    from wholebody.robot.robot import Robot

__all__ = ["RobotKinematics", "pack_model"]

_SE3_DOUBLES = 12  # rotation (3 x 3, column-major), translation (3)

_KINDS = {
    "REVOLUTE": ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"),
    "UNBOUNDED": (
        "JointModelRUBX",
        "JointModelRUBY",
        "JointModelRUBZ",
        "JointModelRevoluteUnboundedUnaligned",
    ),
    "PRISMATIC": ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"),
    "PLANAR": ("JointModelPlanar",),
    "FREE_FLYER": ("JointModelFreeFlyer",),
}
"""The kinds of :mod:`wholebody.kernels.forward` and Pinocchio's joint types of each."""


class RobotKinematics:
    """The compiled core's view of one robot (see the module docstring).

    Attributes
    ----------
    act_k, act_j, act_a
        The non-zero entries of the actuation matrix ``A`` (nv x nu): ``A[j, k] = a``.
    position_index, position_pair
        Per actuated velocity, the index into ``q`` of its scalar position, and how it is
        stored there: a scalar, an angle as a (cos, sin) pair (wheels, continuous joints, a
        planar base's yaw), or a floating base's roll, pitch or yaw of its quaternion (see
        :func:`wholebody.kernels.kinematics.joint_positions`; made on first use).
    fast
        Whether :meth:`views` returns views of Pinocchio's memory (False: copies).
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        A = robot.actuation
        k, j = np.nonzero(A.T)
        self.act_k = k.astype(np.int64)
        self.act_j = j.astype(np.int64)
        self.act_a = np.ascontiguousarray(A.T[k, j])
        for arr in (self.act_k, self.act_j, self.act_a):
            arr.setflags(write=False)
        self._tables: tuple[np.ndarray, np.ndarray] | None = None
        self._data: pin.Data | None = None
        self._J = self._oMf = None
        self.fast = False
        self._make_views(robot.data)

    @functools.cached_property
    def _positions(self) -> tuple[np.ndarray, np.ndarray]:
        """``(position_index, position_pair)`` (class docstring)."""
        from wholebody.kernels import kinematics as kk  # (imports numba: only when asked for)

        robot = self.robot
        index = np.zeros(robot.nu, dtype=np.int64)
        how = np.zeros(robot.nu, dtype=np.int64)
        index[robot._scalar] = robot._scalar_q
        index[robot._cont] = robot._cont_q
        how[robot._cont] = kk.ANGLE_PAIR
        virtual = robot._virtual
        if robot.base.floating:  # (x, y, z): q[0:3]; roll, pitch, yaw of the quaternion q[3:7]
            index[virtual] = (0, 1, 2, 3, 3, 3)
            how[virtual[3:]] = (kk.ROLL, kk.PITCH, kk.YAW)
        elif virtual.size:  # a planar base's (x, y, yaw): q[0], q[1], (q[2], q[3])
            index[virtual] = (0, 1, 2)
            how[virtual[2]] = kk.ANGLE_PAIR
        for arr in (index, how):
            arr.setflags(write=False)
        return index, how

    @property
    def position_index(self) -> np.ndarray:
        return self._positions[0]

    @property
    def position_pair(self) -> np.ndarray:
        return self._positions[1]

    def support(self, frames: list[Frame]) -> np.ndarray:
        """(F, nv) boolean: whether each velocity coordinate moves each frame (the columns
        of the joints that support the frame's parent joint)."""
        model = self.robot.model
        out = np.zeros((len(frames), model.nv), dtype=np.bool_)
        for f, frame in enumerate(frames):
            for jid in model.supports[frame.joint]:
                jm = model.joints[jid]
                if jm.nv:
                    out[f, jm.idx_v : jm.idx_v + jm.nv] = True
        return out

    def model_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``(model_i, model_f)``: the robot's model packed for the kernels of
        :mod:`wholebody.kernels.forward` (:func:`pack_model`; made on first use, read-only).
        A :class:`~wholebody.errors.ModelError` names a joint of a type they do not move."""
        if self._tables is None:
            self._tables = pack_model(self.robot.model)
        return self._tables

    def views(self) -> tuple[np.ndarray, np.ndarray]:
        """``(J, oMf)``: ``data.J`` (6 x nv, column-major) and the frame placements
        (nframes, 12) of the robot's data as they are now (after :meth:`Robot.update`)."""
        data = self.robot.data
        if data is not self._data:
            self._make_views(data)
        if self.fast:
            return self._J, self._oMf
        return np.asfortranarray(data.J), _gather(data)

    def _make_views(self, data: pin.Data) -> None:
        self._data = data
        J = data.J
        self._J = J if J.flags.f_contiguous and J.dtype == np.float64 else None
        self._oMf = _placement_view(data)
        self.fast = self._J is not None and self._oMf is not None and self._check(data)

    def _check(self, data: pin.Data) -> bool:
        """Whether the views show what the proxies show, at a random configuration (done when
        the robot is loaded; it leaves the data there and invalidates older states)."""
        robot = self.robot
        q = robot.random_configuration(np.random.default_rng(0))
        robot.update(q)
        return bool(np.array_equal(self._J, data.J) and np.array_equal(self._oMf, _gather(data)))


def pack_model(model: pin.Model) -> tuple[np.ndarray, np.ndarray]:
    """``model`` as the two read-only tables of :mod:`wholebody.kernels.forward`: per joint
    (Pinocchio's order, the universe first) then per frame, ``model_i`` (kind, parent joint,
    idx_q, idx_v) and ``model_f`` (placement in the parent joint, 12 doubles as in
    :meth:`RobotKinematics.views`; a joint's unit axis in its own frame).

    Raises a :class:`~wholebody.errors.ModelError` naming the first joint of a type the
    kernels do not move (they move revolute, continuous, prismatic, planar and free-flyer
    joints)."""
    from wholebody.kernels import forward  # (imports numba: only when the tables are asked for)

    kinds = {t: getattr(forward, kind) for kind, types in _KINDS.items() for t in types}
    q0 = pin.neutral(model)
    nj = model.njoints
    model_i = np.zeros((nj + model.nframes, 4), dtype=np.int64)
    model_f = np.zeros((nj + model.nframes, _SE3_DOUBLES + 3))
    model_i[0, 0] = forward.ROOT
    model_f[0, :_SE3_DOUBLES] = _packed(pin.SE3.Identity())
    for i in range(1, nj):
        jm = model.joints[i]
        kind = kinds.get(jm.shortname(), -1)
        if kind < 0:
            known = ", ".join(t.removeprefix("JointModel") for t in kinds)
            raise ModelError(
                f"joint {model.names[i]!r} is a {jm.shortname()}: the compiled kinematics "
                f"move these joint types only: {known}"
            )
        model_i[i] = kind, model.parents[i], jm.idx_q, jm.idx_v
        model_f[i, :_SE3_DOUBLES] = _packed(model.jointPlacements[i])
        if kind in (forward.REVOLUTE, forward.UNBOUNDED, forward.PRISMATIC):
            # the axis: the motion subspace S = (linear; angular) of a one-velocity joint (not
            # every type's Python binding shows its axis)
            jdata = jm.createData()
            jm.calc(jdata, q0)
            S = np.asarray(jdata.S).reshape(6)
            model_f[i, _SE3_DOUBLES:] = S[:3] if kind == forward.PRISMATIC else S[3:]
    for f, frame in enumerate(model.frames):
        model_i[nj + f, :2] = forward.FRAME, frame.parentJoint
        model_f[nj + f, :_SE3_DOUBLES] = _packed(frame.placement)
    model_i.setflags(write=False)
    model_f.setflags(write=False)
    return model_i, model_f


def _packed(M: pin.SE3) -> np.ndarray:
    """A placement as 12 doubles: rotation in column-major order, then translation (m)."""
    return np.concatenate((M.rotation.ravel(order="F"), M.translation))


def _gather(data: pin.Data) -> np.ndarray:
    """The frame placements (nframes, 12) read through Pinocchio's proxies."""
    out = np.empty((len(data.oMf), _SE3_DOUBLES))
    for i, M in enumerate(data.oMf):
        out[i, :9] = M.rotation.ravel(order="F")
        out[i, 9:] = M.translation
    return out


def _placement_view(data: pin.Data) -> np.ndarray | None:
    """A view (nframes, 12) of ``data.oMf``'s memory, or None when the proxies do not show
    the contiguous layout of 12 doubles per frame that the view assumes."""
    frames = data.oMf
    n = len(frames)
    if n == 0:
        return None
    first = frames[0]
    R, t = first.rotation, first.translation
    if R.flags.owndata or t.flags.owndata or not R.flags.f_contiguous:
        return None  # copies, not views of the data
    base = R.__array_interface__["data"][0]
    step = _SE3_DOUBLES * 8
    if t.__array_interface__["data"][0] != base + 72:
        return None
    if n > 1 and frames[1].rotation.__array_interface__["data"][0] != base + step:
        return None
    buffer = (ctypes.c_double * (n * _SE3_DOUBLES)).from_address(base)
    return np.ctypeslib.as_array(buffer).reshape(n, _SE3_DOUBLES)
