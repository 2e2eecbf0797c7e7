"""The arm angle people choose, as an objective and as a task, and a signed spring.

The arm angle ``alpha`` (:mod:`wholebody.arm.angle`: 0 with the elbow at its lowest, > 0
swung outwards, mirrored arms) is what makes a redundant arm look human: for one wrist
position people hold the elbow in a narrow band (most frames in [0, 0.8] rad).

* :class:`HumanArmAngle`: ``f = 1/2 w (alpha - alpha_h(p))^2`` with ``alpha_h`` a model of
  the human arm angle (:class:`wholebody.arm.HumanArmAngleModel`) at the wrist relative to the
  shoulder in the arm's canonical axes, divided by the arm's length:
  ``p = Mirror R_b^T (W - S) / (L1 + L2)`` (dimensionless, so that a model learned on people
  transfers to the robot's arm). ``alpha - alpha_h`` is wrapped into (-pi, pi].
* :class:`HumanArmAngleTask`: the same residual as a task row, ``d(alpha - alpha_h) u =
  -kp (alpha - alpha_h)``, for a level of its own below the hands: the residual decays at a
  set rate wherever the hands leave the elbow free, and ``alpha_h``'s motion with the wrist is
  in the row, so it is followed without lag. The objective instead trades the residual
  against the rest of ``H`` (the gravity energy, joint-limit avoidance) at its weight.
* :class:`ArmAngleSpring`: the paper's torsion spring ``1/2 k (pi - |alpha|)^2 w`` acts on
  ``|alpha|``: an elbow tucked in (``alpha < 0``) is pushed further in. With
  ``signed=True`` it is ``1/2 k (pi - alpha)^2 w`` on the signed angle, which pulls a tucked
  elbow out through 0 (it jumps at ``alpha = -pi``, the elbow at the top of its circle and
  swung in, far from where arms work).

Both fade out where the arm angle is undefined (a straight arm, a vertical shoulder-wrist
line): ``w = rho^2 / (rho^2 + eps^2)``, ``rho^2 = x^2 + y^2`` (see :mod:`wholebody.arm.angle`),
as the arm energy's spring does. Gradients in actuated coordinates, with ``J_S, J_E, J_W`` the
linear Jacobians of the joint centres and ``J_b`` the base frame's::

    d alpha = sum_X (d alpha / dX) J_X,     d rho^2 = 2 (x dx + y dy)
    d p = Mirror R_b^T (J_W - J_S + [W - S]x J_b,ang) / (L1 + L2)

:class:`HumanArmAngle` reports ``curvature``, a diagonal bound ``c_i = w |a_i| sum_j |a_j|``
on its Gauss-Newton Hessian ``w a a^T`` (``a = d(alpha - alpha_h)``; Gershgorin: ``diag(c) -
w a a^T`` is diagonally dominant, so positive semi-definite). With it the stack's
semi-implicit step (before the projection into the tasks' null space) moves
``alpha - alpha_h`` by less than its value at any weight: a heavy pull converges instead of
oscillating from one control step to the next.

They are evaluated in Python (the compiled plan copies their gradients in).
"""

from __future__ import annotations

import math
import numbers
from typing import Protocol

import numpy as np

from wholebody.arm.angle import arm_angle_with_gradient
from wholebody.arm.stiffness import ConstantStiffness, StiffnessModel
from wholebody.errors import DimensionError
from wholebody.robot import ArmChain, Frame, Robot, RobotState
from wholebody.tasks.base import Objective, ObjectiveValue, Task, TaskRows

__all__ = ["ArmAngleModel", "ArmAngleSpring", "HumanArmAngle", "HumanArmAngleTask"]


class ArmAngleModel(Protocol):
    """What :class:`HumanArmAngle` asks of a model of the human arm angle: ``evaluate(p)``
    returns ``alpha_h`` (rad) and its gradient (3,) at the normalised canonical wrist ``p``."""

    def evaluate(self, p: np.ndarray) -> tuple[float, np.ndarray]: ...


class _ArmAngleObjective(Objective):
    """What both objectives share: the arm's frames, the fade and the arm angle's and the
    canonical wrist's derivatives at a state."""

    def __init__(
        self, robot: Robot, arm: str | ArmChain, name: str, weight: float, fade: float
    ) -> None:
        self.robot = robot
        self.arm = arm if isinstance(arm, ArmChain) else robot.arm(arm)
        super().__init__(name, weight)
        if not (math.isfinite(fade) and fade > 0):
            raise DimensionError(f"{self.name}: fade must be a finite number > 0 m, got {fade}")
        self.fade = float(fade)
        self.side = 1.0 if self.arm.side == "left" else -1.0
        self.mirror = np.array([1.0, -self.side, 1.0])  # canonical y = medial
        self.reach = self.arm.upper_arm_length + self.arm.forearm_length
        a = self.arm
        self._frames = (a.shoulder, a.elbow, a.wrist, robot.base_frame)

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return self._frames

    def _angle(self, state: RobotState):
        """The arm angle with its gradients, its fade ``w`` and ``dw`` factors, and the
        positions."""
        S, E, W = (state.position(f) for f in self._frames[:3])
        arm = arm_angle_with_gradient(S, E, W, self.side)
        eps2 = self.fade * self.fade
        w = arm.rho2 / (arm.rho2 + eps2)
        return arm, w, eps2, (S, E, W)

    def _d_alpha(self, state: RobotState, arm, eps2: float) -> tuple[np.ndarray, np.ndarray]:
        """``(w d alpha, dw)`` in actuated coordinates (nu,) each: bounded where alpha is
        undefined, because ``w d alpha = (x dy - y dx) / (rho^2 + eps^2)``."""
        den = arm.rho2 + eps2
        g_alpha = (arm.x * arm.dy - arm.y * arm.dx) / den  # (3, 3): rows S, E, W
        g_rho2 = 2.0 * (arm.x * arm.dx + arm.y * arm.dy) * eps2 / (den * den)
        J = [state.jacobian(f)[:3] for f in self._frames[:3]]
        w_dalpha = sum(g_alpha[i] @ J[i] for i in range(3))
        dw = sum(g_rho2[i] @ J[i] for i in range(3))
        return w_dalpha, dw

    def _wrist(self, state: RobotState, S: np.ndarray, W: np.ndarray):
        """``p`` (the canonical wrist over the arm's length) and ``dp/du`` (3 x nu)."""
        Rb = state.rotation(self._frames[3])
        d = W - S
        p = self.mirror * (Rb.T @ d) / self.reach
        Jw, Js = state.jacobian(self._frames[2])[:3], state.jacobian(self._frames[0])[:3]
        Jb = state.jacobian(self._frames[3])[3:]
        skew = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
        dp = (self.mirror[:, None] * (Rb.T @ (Jw - Js + skew @ Jb))) / self.reach
        return p, dp


class HumanArmAngle(_ArmAngleObjective):
    """Pull the arm angle towards the human one: ``f = 1/2 w (alpha - alpha_h(p))^2``
    (rad^2; see the module docstring).

    Parameters
    ----------
    robot, arm
        The robot and its arm (name or :class:`ArmChain`).
    model
        The human arm angle ``alpha_h(p)`` (:func:`wholebody.arm.default_arm_angle_model`,
        or any object with ``evaluate(p) -> (alpha_h, d alpha_h / d p)``).
    weight
        Its coefficient in the level's ``H``.
    fade
        ``eps`` (m) of the fade where the arm angle is undefined.
    """

    def __init__(
        self,
        robot: Robot,
        arm: str | ArmChain,
        model: ArmAngleModel,
        *,
        weight: float = 1.0,
        fade: float = 0.01,
        name: str | None = None,
    ) -> None:
        chain = arm if isinstance(arm, ArmChain) else robot.arm(arm)
        super().__init__(robot, chain, name or f"{chain.name}_human_arm_angle", weight, fade)
        if isinstance(model, StiffnessModel) or not callable(getattr(model, "evaluate", None)):
            raise DimensionError(
                f"{self.name}: model must have evaluate(p) -> (alpha, gradient), got {model!r}"
            )
        self.model = model

    def target(self, state: RobotState) -> float:
        """``alpha_h`` (rad) at ``state``'s wrist."""
        S, W = state.position(self._frames[0]), state.position(self._frames[2])
        return self._model_at(
            self.mirror * (state.rotation(self._frames[3]).T @ (W - S)) / self.reach
        )[0]

    def residual(self, state: RobotState) -> tuple[float, float, np.ndarray, np.ndarray]:
        """``(e, w, w de, dw)``: the wrapped residual ``e = alpha - alpha_h`` (rad), the fade
        ``w``, and in actuated coordinates (nu,) ``w d e`` (bounded where alpha is undefined)
        and ``d w``."""
        arm, w, eps2, (S, _, W) = self._angle(state)
        p, dp = self._wrist(state, S, W)
        alpha_h, g_h = self._model_at(p)
        e = math.remainder(arm.alpha - alpha_h, 2.0 * math.pi)
        w_dalpha, dw = self._d_alpha(state, arm, eps2)
        return e, w, w_dalpha - w * (g_h @ dp), dw

    def _model_at(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """``alpha_h`` (rad) and its gradient (3,) at ``p``, checked: a model that answers a
        non-finite angle or a gradient of another shape is named, not passed to a solver."""
        alpha_h, g_h = self.model.evaluate(p)
        g = np.asarray(g_h, dtype=float)
        alpha = float(alpha_h)
        if g.shape != (3,) or not (math.isfinite(alpha) and np.all(np.isfinite(g))):
            raise DimensionError(
                f"{self.name}: the arm-angle model must return a finite "
                f"angle (rad) and gradient of shape (3,) at p = {p}, got "
                f"{alpha_h!r} and shape {g.shape}"
            )
        return alpha, g

    def evaluate(self, state: RobotState) -> ObjectiveValue:
        e, w, w_de, dw = self.residual(state)
        grad = e * w_de + 0.5 * e * e * dw
        # a diagonal bound on the Gauss-Newton Hessian w de de^T (Gershgorin: |a_i| sum |a_j|
        # >= a a^T), so that the semi-implicit descent step never overshoots alpha_h
        a = np.abs(w_de)
        curvature = a * (a.sum() / w) if w > 1e-12 else np.zeros_like(a)
        return ObjectiveValue(0.5 * w * e * e, grad, curvature)


class HumanArmAngleTask(Task):
    """The arm angle as a task: one row ``w de/du u = w^2 sat(-kp (alpha - alpha_h(p)))``
    (rad/s; ``e = alpha - alpha_h``, ``sat`` clips to ``+-max_rate``, ``w`` the fade of the
    module docstring with ``eps = fade``).

    Where the levels above leave the arm's self-motion free, ``e`` decays at the rate
    ``w kp`` (1/s), at most ``w max_rate`` rad/s. ``alpha_h`` moves with the wrist and its
    rate enters the row through ``d alpha_h / dp``, so a moving wrist is followed without lag.
    Why the limits: an elbow far from ``alpha_h`` (a start posture) would otherwise ask the
    joints for several rad/s at once and saturate their velocity and acceleration limits; and
    near a straight arm, where the arm angle turns fast for a small elbow motion and the
    hands' rows are nearly singular, the requested rate fades with ``w`` (``fade`` 3 cm:
    ``w = 0.5`` at ``rho`` = 3 cm, the elbow 3 cm off a horizontal shoulder-wrist line;
    ``rho`` shrinks as that line tilts towards the vertical, :mod:`wholebody.arm.angle`).

    ``arm_only`` (default): the row acts on the arm's joints only (its group in
    ``robot.toml``), the waist and base are left to the tasks and ``H``; else on every
    joint.
    """

    def __init__(
        self,
        robot: Robot,
        arm: str | ArmChain,
        model: ArmAngleModel,
        *,
        kp: float = 10.0,
        max_rate: float = 1.0,
        arm_only: bool = True,
        weight: float = 1.0,
        fade: float = 0.03,
        name: str | None = None,
        lm_damping: float = 0.0,
    ) -> None:
        self.pull = HumanArmAngle(robot, arm, model, fade=fade)
        super().__init__(
            name or f"{self.pull.arm.name}_human_arm_angle", weight, lm_damping=lm_damping
        )
        group = self.pull.arm.group
        if arm_only and group is None:
            raise DimensionError(
                f"{self.name}: arm_only needs the arm's joint group (arms."
                f"{self.pull.arm.name}.group in robot.toml); or pass "
                "arm_only=False"
            )
        self.columns = group.indices if arm_only else None
        for what, value in (("kp", kp), ("max_rate", max_rate)):
            if not (math.isfinite(value) and value >= 0):
                raise DimensionError(
                    f"{self.name}: {what} must be a finite number >= 0, got {value}"
                )
        self.kp, self.max_rate = float(kp), float(max_rate)

    @property
    def dim(self) -> int:
        return 1

    def compute(self, state: RobotState) -> TaskRows:
        e, w, w_de, _ = self.pull.residual(state)
        rate = min(max(-self.kp * e, -self.max_rate), self.max_rate)  # rad/s
        J = w_de[None, :]
        if self.columns is not None:
            J = np.zeros_like(J)
            J[0, self.columns] = w_de[self.columns]
        return TaskRows(J, np.array([w * w * rate]), self.weights)

    def error(self, state: RobotState) -> np.ndarray:
        return np.array([self.pull.residual(state)[0]])

    def jacobian_frames(self) -> tuple[Frame, ...]:
        return self.pull.jacobian_frames()


class ArmAngleSpring(_ArmAngleObjective):
    """A torsion spring on the arm angle, ``1/2 k (pi - |alpha|)^2 w`` as the paper's, or with
    ``signed=True`` ``1/2 k (pi - alpha)^2 w`` (J; see the module docstring). ``stiffness``:
    a constant (N m/rad) or a :class:`~wholebody.arm.StiffnessModel` of the canonical wrist
    (m), as the arm energy takes."""

    def __init__(
        self,
        robot: Robot,
        arm: str | ArmChain,
        stiffness: float | StiffnessModel,
        *,
        signed: bool = True,
        weight: float = 1.0,
        fade: float = 0.01,
        name: str | None = None,
    ) -> None:
        chain = arm if isinstance(arm, ArmChain) else robot.arm(arm)
        super().__init__(robot, chain, name or f"{chain.name}_arm_angle_spring", weight, fade)
        if not isinstance(stiffness, StiffnessModel):
            if isinstance(stiffness, (str, bool)) or not isinstance(stiffness, numbers.Real):
                raise DimensionError(
                    f"{self.name}: stiffness must be a number (N m/rad) or a "
                    f"StiffnessModel, got {stiffness!r}"
                )
            stiffness = ConstantStiffness(float(stiffness))
        self.stiffness, self.signed = stiffness, bool(signed)

    def evaluate(self, state: RobotState) -> ObjectiveValue:
        arm, w, eps2, (S, _, W) = self._angle(state)
        p, dp = self._wrist(state, S, W)
        k, dk = self.stiffness.evaluate(p * self.reach)  # the stiffness model takes metres
        sign = 1.0 if self.signed or arm.alpha >= 0 else -1.0
        rest = math.pi - sign * arm.alpha
        w_dalpha, dw = self._d_alpha(state, arm, eps2)
        grad = -k * rest * sign * w_dalpha + 0.5 * rest * rest * (k * dw)
        if np.any(dk):
            grad = grad + 0.5 * rest * rest * w * self.reach * (np.asarray(dk) @ dp)
        return ObjectiveValue(0.5 * k * rest * rest * w, grad)
