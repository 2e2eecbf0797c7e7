"""The paper's arm potential energy ``f_p = f_g + f_e`` as an objective.

* Gravity: ``f_g = g (m1 h1 + m2 h2)``, the heights (m) of the upper-arm and forearm centres
  of mass, masses and centres of mass from the robot model (hand excluded). **Decision:**
  heights are measured from the arm's shoulder centre (``reference="shoulder"``, default), so
  the energy describes the arm's posture: bending the waist or lowering the body earns
  nothing. (With world heights, ``reference="world"``, leaning the trunk forward lowers both
  centres of mass, and the objective then rewards exactly the waist motion the paper's
  method is meant to avoid.) The stiffness label ``d f_g / d alpha`` at fixed shoulder and
  wrist is the same with either reference.
* Virtual torsion spring about the shoulder-wrist line: ``f_e = 1/2 k (pi - |alpha|_s)^2 w``
  with the arm angle alpha (:mod:`wholebody.arm.angle`, 0 = elbow lowest), rest
  angle pi, and stiffness k constant or a model ``k(wrist)``
  (:class:`~wholebody.arm.stiffness.StiffnessModel`).

Two regularisations make the energy smooth everywhere (documented decisions):

* ``|alpha|_s`` is the Huber-smoothed magnitude: ``alpha^2 / (2 delta) + delta / 2`` for
  ``|alpha| < delta``, else ``|alpha|`` (``delta`` = ``smoothing``, rad). It equals |alpha|
  away from 0, so the spring is the paper's there, and its gradient does not jump where the
  elbow passes its lowest point.
* ``w = rho^2 / (rho^2 + eps^2)`` with ``rho^2 = x^2 + y^2 = |d|^2 sin^2(theta_u)``, eps =
  ``fade`` (m): alpha is undefined for a straight arm or a vertical shoulder-wrist line
  (``rho = 0``), where rotating about that line changes nothing, so the spring fades out
  there. ``w dalpha = (x dy - y dx) / (rho^2 + eps^2)`` stays bounded, and the gradient exists
  everywhere. With eps = 1 cm, w > 0.96 once rho > 5 cm.

Gradient in actuated coordinates, with ``J_S, J_E, J_W`` the linear Jacobians of the joint
centres, ``J_c1, J_c2`` those of the centres of mass and ``s = |alpha|_s``::

    d f_g = g (m1 (J_c1[z] - J_S[z]) + m2 (J_c2[z] - J_S[z]))     (shoulder reference)
    d f_e = 1/2 (pi - s)^2 w dk  -  k (pi - s) s'(alpha) w dalpha  +  1/2 k (pi - s)^2 dw

A segment whose mass is split over several links (``upper_arm = ["a", "b"]`` in robot.toml)
adds ``g m_i h_i`` per link; the kernels hold one link per segment, so an arm with more is
evaluated here: the kernel's two, plus the others with their centre-of-mass Jacobians.

The stiffness model's input is the wrist relative to the shoulder in the arm's canonical body
axes (x forward, y medial, z up; see :mod:`wholebody.arm.stiffness`):
``p = Mirror R_b^T (W - S)`` with ``R_b`` the base yaw, so
``dp = Mirror R_b^T (J_W - J_S + [W - S]x J_b,ang)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.arm.stiffness import ConstantStiffness, StiffnessModel
from wholebody.errors import DimensionError
from wholebody.kernels.layout import KIND_ARM
from wholebody.kernels.objectives import (
    AE_COM1,
    AE_COM2,
    AE_CONSTANT,
    AE_DK,
    AE_FADE,
    AE_G,
    AE_GIVEN,
    AE_K,
    AE_M1,
    AE_M2,
    AE_NET,
    AE_SHOULDER,
    AE_SIDE,
    AE_SMOOTH,
    AE_WIDTH,
    ARM_PARTS,
    arm_energy,
)
from wholebody.robot import ArmChain, Body, Frame, Robot, RobotState
from wholebody.tasks.base import Objective, ObjectiveValue, Packed, Packer

__all__ = ["ArmEnergyValue", "ArmPotentialEnergy"]


@dataclass(frozen=True)
class ArmEnergyValue(ObjectiveValue):
    """The arm energy with its parts, for logging (J, J, rad, N m/rad, m). ``rho`` is
    ``|d| sin(theta_u)``, how well the arm angle is defined (0: undefined)."""

    gravity: float = 0.0
    spring: float = 0.0
    arm_angle: float = 0.0
    stiffness: float = 0.0
    rho: float = 0.0


class ArmPotentialEnergy(Objective):
    """Gravity plus virtual-spring energy of one arm (J).

    Parameters
    ----------
    robot, arm
        The robot and the arm chain (name or :class:`~wholebody.robot.ArmChain`).
    stiffness
        Constant k (N m/rad) or a :class:`StiffnessModel`.
    smoothing
        ``delta`` of the smoothed |alpha| (rad).
    fade
        ``eps`` of the spring's fade-out where alpha is undefined (m).
    reference
        ``"shoulder"`` (default) or ``"world"``: what the heights of the gravity term are
        measured from (see the module docstring).
    """

    def __init__(
        self,
        robot: Robot,
        arm: str | ArmChain,
        stiffness: float | StiffnessModel,
        *,
        weight: float = 1.0,
        smoothing: float = 0.05,
        fade: float = 0.01,
        reference: str = "shoulder",
        name: str | None = None,
    ) -> None:
        self.robot = robot
        self.arm = arm if isinstance(arm, ArmChain) else robot.arm(arm)
        super().__init__(name or f"{self.arm.name}_arm_energy", weight)
        if not smoothing > 0 or not fade > 0:
            raise DimensionError(f"{self.name}: smoothing and fade must be > 0")
        if reference not in ("shoulder", "world"):
            raise DimensionError(
                f"{self.name}: reference must be 'shoulder' or 'world', got {reference!r}"
            )
        self.side = 1.0 if self.arm.side == "left" else -1.0
        self._mirror = np.array([1.0, -self.side, 1.0])  # canonical y = medial
        arm = self.arm
        self._frames = (arm.shoulder, arm.elbow, arm.wrist, arm.upper_arm.frame, arm.forearm.frame)
        self._frames_base = (*self._frames, robot.base_frame)
        self._settings = (float(smoothing), float(fade), reference)
        self.stiffness = stiffness  # (lays out the parameter block)

    @property
    def stiffness(self) -> StiffnessModel:
        """``k``: a :class:`ConstantStiffness` or a model of the wrist position (assigning a
        number makes a constant one)."""
        return self._stiffness

    @stiffness.setter
    def stiffness(self, value: float | StiffnessModel) -> None:
        if isinstance(value, StiffnessModel):
            self._stiffness = value
        else:
            try:  # a number, a numpy scalar or 0-d array; not a string such as "learned"
                k = float(value) if not isinstance(value, str) else None
            except (TypeError, ValueError):
                k = None
            if k is None:
                raise DimensionError(
                    f"{self.name}: stiffness must be a number (N m/rad) or a StiffnessModel "
                    "(the learned one: wholebody.humanlike.default_stiffness(robot)), got "
                    f"{value!r}"
                )
            self._stiffness = ConstantStiffness(k)
        self._params = self._block()  # a new block: a stack lays it out again

    @property
    def smoothing(self) -> float:
        """``delta`` of the smoothed |alpha| (rad)."""
        return self._settings[0]

    @property
    def fade(self) -> float:
        """``eps`` of the spring's fade-out where alpha is undefined (m)."""
        return self._settings[1]

    @property
    def reference(self) -> str:
        """What the gravity term's heights are measured from: ``"shoulder"`` or ``"world"``."""
        return self._settings[2]

    @property
    def g(self) -> float:
        """Gravity (m/s^2), from the robot model."""
        return float(np.linalg.norm(self.robot.model.gravity.linear))

    def _block(self) -> np.ndarray:
        """The kernel's parameter block: ``AE_*`` parameters, ``ARM_PARTS`` outputs, then the
        packed stiffness network if the kernels evaluate it."""
        arm = self.arm
        par = np.zeros(AE_WIDTH)
        par[AE_G], par[AE_M1], par[AE_M2] = self.g, arm.upper_arm.mass, arm.forearm.mass
        par[AE_COM1 : AE_COM1 + 3] = arm.upper_arm.com
        par[AE_COM2 : AE_COM2 + 3] = arm.forearm.com
        par[AE_SIDE], par[AE_FADE], par[AE_SMOOTH] = self.side, self.fade, self.smoothing
        par[AE_SHOULDER] = self.reference == "shoulder"
        net = self.network()
        stiffness = self._stiffness
        if type(stiffness) is ConstantStiffness:  # k does not depend on the wrist
            par[AE_K], par[AE_NET] = stiffness.k, AE_CONSTANT
        elif net is not None:
            par[AE_NET] = 0
        else:  # evaluated in Python at each call (_kernel_energy)
            par[AE_NET] = AE_GIVEN
        return np.concatenate([par, np.zeros(ARM_PARTS), np.zeros(0) if net is None else net])

    def jacobian_frames(self) -> tuple[Frame, ...]:
        """Shoulder, elbow, wrist, upper-arm and forearm frames, and the base frame when the
        stiffness depends on the wrist position."""
        return self._frames if isinstance(self._stiffness, ConstantStiffness) else self._frames_base

    def network(self) -> np.ndarray | None:
        """The stiffness as a packed network the kernels evaluate themselves, or None (a
        constant, or a model evaluated in Python)."""
        packed = getattr(self._stiffness, "packed", None)
        return packed() if callable(packed) else None

    def pack(self, packer: Packer) -> Packed | None:
        """Compiled where the kernels evaluate the stiffness (a constant or a packed network)
        and each segment is one link (see the module docstring)."""
        if (
            self.extra_bodies
            or self._params[AE_NET] == AE_GIVEN
            or not self.compiled_as(ArmPotentialEnergy, "evaluate", "_energy")
        ):
            return None
        frames = self._frames_base if self.network() is not None else self._frames
        ints = [packer.frame(f) for f in frames] + [-1] * (6 - len(frames))
        return Packed(KIND_ARM, self._params, np.array(ints, dtype=np.int64))

    def evaluate(self, state: RobotState) -> ArmEnergyValue:
        grad = np.empty(self.robot.nu)
        parts = self._energy(state, state.jacobians(self._frames_base), grad)
        value, gravity, spring, alpha, k, rho = parts.tolist()
        return ArmEnergyValue(
            value=value,
            gradient=grad,
            gravity=gravity,
            spring=spring,
            arm_angle=alpha,
            stiffness=k,
            rho=rho,
        )

    def parts(self, state: RobotState) -> np.ndarray:
        """``(value, gravity, spring, arm_angle, stiffness, rho)`` (J, J, J, rad, N m/rad, m)
        at ``state``, without the gradient (no Jacobians: what a monitor logs)."""
        return self._energy(state, _NO_JACOBIAN, _NO_GRADIENT)

    @property
    def extra_bodies(self) -> tuple[Body, ...]:
        """The links of the arm's segments beyond the first of each (see the module
        docstring): their gravity is added outside the kernel."""
        arm = self.arm
        return arm.upper_arm_bodies[1:] + arm.forearm_bodies[1:]

    def _energy(self, state: RobotState, J: np.ndarray, grad: np.ndarray) -> np.ndarray:
        """``ARM_PARTS`` at ``state`` (the kernel's, with the extra links' gravity), the
        gradient into ``grad`` (``J``: the frames' Jacobians, one column per entry of
        ``grad``; none: no gradient)."""
        parts = self._kernel_energy(state, J, grad)
        extra = self.extra_bodies
        if extra:
            shoulder = self.reference == "shoulder"
            base = state.position(self.arm.shoulder)[2] if shoulder else 0.0
            gravity = sum(self.g * b.mass * (state.com_position(b)[2] - base) for b in extra)
            parts[0] += gravity
            parts[1] += gravity
            if grad.size:
                for b in extra:
                    grad += self.g * b.mass * state.com_jacobian(b)[2]
                    if shoulder:
                        grad -= self.g * b.mass * state.jacobian(self.arm.shoulder)[2]
        return parts

    def _kernel_energy(self, state: RobotState, J: np.ndarray, grad: np.ndarray) -> np.ndarray:
        """The kernel's ``ARM_PARTS`` at ``state`` (the first link of each segment), its
        gradient into ``grad``."""
        P = np.empty((6, 3))
        R = np.empty((6, 3, 3))
        for i, f in enumerate(self._frames_base):
            R[i], P[i] = state.rotation_translation(f)
        par = self._params[:AE_WIDTH]
        if par[AE_NET] == AE_GIVEN:  # a model evaluated here, at Mirror R_b^T (W - S)
            par = par.copy()
            wrist = self._mirror * R[5].T.dot(P[2] - P[0])
            par[AE_K], par[AE_DK : AE_DK + 3] = self._stiffness.evaluate(wrist)
        parts = self._params[AE_WIDTH : AE_WIDTH + ARM_PARTS]
        arm_energy(P, R, J, par, self._params[AE_WIDTH + ARM_PARTS :], grad, parts)
        return parts.copy()

    def same_energy(self, other: object) -> bool:
        """Whether ``other`` is an arm energy with the same value as this one at every state
        (same arm, stiffness and settings; the weight and name may differ)."""
        if not isinstance(other, ArmPotentialEnergy):
            return False
        a, b = self.stiffness, other.stiffness
        same_k = a is b or (type(a) is type(b) is ConstantStiffness and a.k == b.k)
        return (
            same_k
            and self.arm is other.arm
            and self.robot is other.robot
            and self._settings == other._settings
        )


_NO_JACOBIAN = np.zeros((6, 6, 0))  # parts(): the gradient has no columns
_NO_GRADIENT = np.zeros(0)
