"""Inequality tasks: keep a frame on one side of a plane.

:class:`FrameHalfSpace` keeps a frame's origin ``p`` in the half-space ``n . p >= d`` (unit
normal ``n``, world axes): a table top below the hands, a wall beside the robot. As a velocity
inequality for one control step of ``dt`` seconds, with ``J_lin`` the frame's linear Jacobian::

    n^T J_lin u  >=  gain (d - n . p) / dt

With ``gain <= 1`` a step never crosses the plane (to first order): inside the half-space the
right-hand side is negative (the frame may approach the plane, covering at most ``gain`` of the
remaining distance per step); outside it is positive, and the frame is pushed back. Only the
hierarchical QP backend takes inequality tasks.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wholebody.errors import DimensionError
from wholebody.kernels.layout import KIND_HALF_SPACE
from wholebody.kernels.rows import half_space_row
from wholebody.robot import Frame, Robot, RobotState
from wholebody.tasks.base import InequalityRows, InequalityTask, Packed, Packer

__all__ = ["FrameHalfSpace"]


class FrameHalfSpace(InequalityTask):
    """Keep a frame's origin in ``normal . p >= offset`` (one row).

    Parameters
    ----------
    robot, frame
        The robot and the frame (name or :class:`Frame`).
    normal
        The plane's normal (world axes), pointing into the allowed side; normalised here.
    offset
        ``d`` (m): the plane is ``normal . p = offset``.
    gain
        Fraction of the remaining distance to the plane one step may cover, in (0, 1].
    """

    def __init__(
        self,
        robot: Robot,
        frame: str | Frame,
        normal: Sequence[float] | np.ndarray,
        offset: float,
        *,
        gain: float = 0.5,
        name: str | None = None,
    ) -> None:
        nrm = np.asarray(normal, dtype=float)
        self.frame = robot.frame(frame)
        self.name = name or f"{self.frame.name}_half_space"
        length = float(np.linalg.norm(nrm)) if nrm.shape == (3,) else 0.0
        if not (np.isfinite(length) and length > 0):
            raise DimensionError(f"{self.name}: normal must be a non-zero 3-vector, got {normal!r}")
        if not (np.isfinite(offset) and 0 < gain <= 1):
            raise DimensionError(f"{self.name}: offset must be finite and gain in (0, 1]")
        self.robot = robot
        self._params = np.array([*(nrm / length), offset, gain])  # the kernel's block
        self._params.setflags(write=False)

    @property
    def normal(self) -> np.ndarray:
        """The unit normal (world axes), fixed at construction (read-only)."""
        return self._params[:3]

    @property
    def offset(self) -> float:
        """``d`` (m), fixed at construction."""
        return float(self._params[3])

    @property
    def gain(self) -> float:
        """Fraction of the remaining distance one step may cover, fixed at construction."""
        return float(self._params[4])

    @property
    def dim(self) -> int:
        return 1

    def distance(self, state: RobotState) -> float:
        """Signed distance (m) of the frame to the plane, positive on the allowed side."""
        return float(self.normal @ state.position(self.frame)) - self.offset

    def compute(self, state: RobotState, dt: float) -> InequalityRows:
        C = np.empty((1, self.robot.nu))
        p = state.rotation_translation(self.frame)[1]
        lower = half_space_row(
            state.jacobian(self.frame), p, self.normal, self.offset, self.gain, dt, C[0]
        )
        return InequalityRows(C, np.array([lower]), np.array([np.inf]))

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return (self.frame,)

    def pack(self, packer: Packer) -> Packed | None:
        if not self.compiled_as(FrameHalfSpace, "compute"):
            return None
        return Packed(
            KIND_HALF_SPACE,
            self._params.copy(),
            np.array([packer.frame(self.frame)], dtype=np.int64),
        )

    def __repr__(self) -> str:
        return f"FrameHalfSpace({self.name!r}, normal={self.normal}, offset={self.offset})"
