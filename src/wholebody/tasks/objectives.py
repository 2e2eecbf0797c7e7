"""Configuration objectives of the paper: joint-limit avoidance ``h1`` and manipulability ``h2``.

Both return a value and its analytic gradient in actuated coordinates (see
:class:`~wholebody.tasks.base.Objective`); the paper's ``H = w1 f_p + w2 h1 - w3 h2`` is the
weighted sum a stack level forms from its objectives (manipulability with a negative weight).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence

import numpy as np
from scipy.linalg.lapack import dpotrf, dtrtri

from wholebody.errors import DimensionError, WholebodyError
from wholebody.robot import Frame, Robot, RobotState
from wholebody.robot.hessian import JacobianDerivativeContraction
from wholebody.tasks.base import Objective, ObjectiveValue

__all__ = ["JointLimitAvoidance", "Manipulability"]

_sum = np.add.reduce  # ndarray.sum() without its Python wrapper
_PIVOT_FLOOR = 1e-8  # Cholesky pivots^2 below this fraction of max diag(J J^T): LU decides


class JointLimitAvoidance(Objective):
    """The paper's ``h1 = sum_i (qmax_i - qmin_i)^2 / (4 (qmax_i - q_i)(q_i - qmin_i))``.

    Summed over the joints with finite limits (by default all of them: the 19 revolute joints
    of the paper's robot; wheels have none). It is 1 per joint at mid-range and grows without
    bound at a limit. Gradient, with ``a = qmax - q``, ``b = q - qmin``, ``c = range^2 / 4``:
    ``d h1 / d q = c (b - a) / (a b)^2``; the Hessian is diagonal,
    ``d2 h1 / d q2 = 2 c (a b + (b - a)^2) / (a b)^3``, and is reported as ``curvature`` so the
    descent step stays stable however steep h1 gets near a limit. A joint at or beyond a limit
    is evaluated at ``range * 1e-6`` inside it, so value and gradient stay finite and point
    inwards.

    Parameters
    ----------
    joints
        Group names, joint names and/or indices into ``u`` to include (default: every joint
        with finite limits); a name is a group's before a joint's.
    """

    def __init__(self, robot: Robot, joints: Sequence[str | int] | None = None, *,
                 weight: float = 1.0, name: str = "joint_limit_avoidance") -> None:  # fmt: skip
        lower, upper = robot.position_limits
        limited = np.isfinite(lower) & np.isfinite(upper)
        if isinstance(joints, str):  # one group or joint name
            joints = [joints]
        if joints is None:
            idx = np.flatnonzero(limited)
        else:
            for j in joints:
                if isinstance(j, (int, np.integer)):
                    if not 0 <= j < robot.nu:
                        raise WholebodyError(f"{name}: index {j} is not in [0, {robot.nu})")
                    continue
                if j not in robot.groups and j not in robot.actuated_joints:
                    close = difflib.get_close_matches(j, [*robot.groups, *robot.actuated_joints])
                    raise WholebodyError(
                        f"{name}: {j!r} is neither a joint group ({', '.join(robot.groups)}) nor "
                        "an actuated joint"
                        + (f" (did you mean {', '.join(map(repr, close))}?)" if close else "")
                    )
            parts = [[int(j)] if isinstance(j, (int, np.integer)) else robot.groups[j].indices
                     if j in robot.groups else [robot.index(j)] for j in joints]  # fmt: skip
            idx = np.unique(np.concatenate(parts)).astype(int)
            if not np.all(limited[idx]):
                bad = [robot.actuated_joints[i] for i in idx if not limited[i]]
                raise WholebodyError(f"{name}: joints without position limits: {bad}")
        if idx.size == 0:
            raise WholebodyError(f"{name}: no joint with finite limits to act on")
        self.name, self.weight, self.robot = name, float(weight), robot
        self.indices = idx
        self._lo, self._hi = lower[idx], upper[idx]
        span = self._hi - self._lo
        self._c = span**2 / 4
        self._eps = 1e-6 * span
        # Evaluated over all nu entries at once (no gather/scatter): every joint with finite
        # limits over its range, the others over the dummy range [-1, 1]; the joints left out
        # get c = 0, so they contribute exact zeros. The ranges are the same for every
        # instance on this robot, so the terms that do not involve c are computed once per
        # state and shared (see _terms).
        nu = robot.nu
        lo, hi, c = np.full(nu, -1.0), np.full(nu, 1.0), np.zeros(nu)
        lo[limited], hi[limited] = lower[limited], upper[limited]
        c[idx] = self._c
        self._lo_all, self._hi_all, self._c_all, self._c2_all = lo, hi, c, 2 * c
        eps = 1e-6 * (hi - lo)
        self._qmin_all, self._qmax_all = lo + eps, hi - eps

    def _terms(self, state: RobotState) -> tuple[np.ndarray, ...]:
        """``(b - a, a b, (a b)^2, (a b)^3, a b + (b - a)^2)`` per actuated velocity, with
        ``a = qmax - q``, ``b = q - qmin`` (q clamped ``range * 1e-6`` inside the limits)."""
        q = np.maximum(state.joint_positions(), self._qmin_all)
        np.minimum(q, self._qmax_all, out=q)
        a = self._hi_all - q
        b = np.subtract(q, self._lo_all, out=q)
        ab = a * b
        d = np.subtract(b, a, out=a)
        ab2 = ab * ab
        ab3 = ab2 * ab
        e = d * d
        e += ab
        return d, ab, ab2, ab3, e

    def evaluate(self, state: RobotState) -> ObjectiveValue:
        d, ab, ab2, ab3, e = state.memo(_TERMS_KEY, self._terms)
        grad = self._c_all * d
        grad /= ab2
        curv = self._c2_all * e
        curv /= ab3
        value = _sum(self._c_all / ab)
        return ObjectiveValue(float(value), grad, curv)


_TERMS_KEY = "joint_limit_avoidance_terms"


class Manipulability(Objective):
    """Yoshikawa's manipulability ``h2 = sqrt(det(J J^T))`` of the frames' stacked Jacobian.

    ``J`` is the 6F x nu actuated Jacobian of the frames (for the paper: both hands, 12 x 23,
    wheel columns through the Mecanum matrix). Gradient, exact:
    ``d h2 / d u_l = h2 <(J J^T)^-1 J, d J / d u_l>_F``, the Jacobian derivatives from the
    kinematic-Hessian identity (:mod:`wholebody.robot.hessian`), never finite differences.
    Where ``J J^T`` is singular (h2 = 0) the gradient is taken as zero.

    To maximise manipulability give it a **negative** weight (the paper's ``-w3 h2``).
    """

    def __init__(self, robot: Robot, frames: Sequence[str | Frame], *, weight: float = -1.0,
                 name: str = "manipulability") -> None:  # fmt: skip
        if isinstance(frames, (str, Frame)):  # one frame, not its characters
            frames = [frames]
        if not frames:
            raise DimensionError(f"{name}: needs at least one frame")
        self.name, self.weight, self.robot = name, float(weight), robot
        self.frames = [robot.frame(f) for f in frames]
        if 6 * len(self.frames) > robot.nu:
            raise DimensionError(f"{name}: {6 * len(self.frames)} rows exceed nu = {robot.nu}; "
                                 "J J^T is always singular")  # fmt: skip
        self._contract = JacobianDerivativeContraction(robot, self.frames)

    def jacobian(self, state: RobotState) -> np.ndarray:
        """The stacked 6F x nu Jacobian."""
        return state.jacobians(self.frames).reshape(6 * len(self.frames), -1).copy()

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return tuple(self.frames)

    def evaluate(self, state: RobotState) -> ObjectiveValue:
        J = state.jacobians(self.frames).reshape(6 * len(self.frames), -1)
        JJt = J.dot(J.T)
        # Cholesky J J^T = L L^T: log det = 2 sum log L_ii and (J J^T)^-1 J = L^-T L^-1 J.
        # Where the smallest pivot is not well above rounding, the LU route decides instead
        # whether J J^T counts as singular (the same answer as before, at a higher cost).
        L, info = dpotrf(JJt, lower=1, clean=1)
        d = L.diagonal() if info == 0 else None
        if d is not None and min(x * x for x in d.tolist()) > _PIVOT_FLOOR * max(
            JJt.diagonal().tolist()
        ):
            logdet = 2.0 * float(_sum(np.log(d)))
            if logdet < -200:
                return ObjectiveValue(0.0, np.zeros(self.robot.nu))
            Linv, _ = dtrtri(L, lower=1)
            P = Linv.T.dot(Linv.dot(J))
        else:
            sign, logdet = np.linalg.slogdet(JJt)
            if sign <= 0 or logdet < -200:
                return ObjectiveValue(0.0, np.zeros(self.robot.nu))
            P = np.linalg.solve(JJt, J)
        h2 = math.exp(0.5 * logdet)
        return ObjectiveValue(h2, h2 * self._contract(state, P, J))
