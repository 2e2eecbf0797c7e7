"""The paper's arm potential energy ``f_p = f_g + f_e`` as an objective.

* Gravity: ``f_g = g sum_i m_i h_i`` over the links of the upper arm and the forearm (hand
  excluded), ``h_i`` the height (m) of link i's centre of mass, masses and centres of mass
  (in the link frames) from the robot model; a segment may be split over several links
  (``forearm = ["a", "b"]`` in robot.toml), the kernel takes any number. **Decision:**
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
  ``|alpha| < delta``, else ``|alpha|`` (``delta`` = ``smoothing``, rad). It equals ``|alpha|``
  away from 0, so the spring is the paper's there, and its gradient does not jump where the
  elbow passes its lowest point.
* ``w = rho^2 / (rho^2 + eps^2)`` with ``rho^2 = x^2 + y^2 = |d|^2 sin^2(theta_u)``, eps =
  ``fade`` (m): alpha is undefined for a straight arm or a vertical shoulder-wrist line
  (``rho = 0``), where rotating about that line changes nothing, so the spring fades out
  there. ``w dalpha = (x dy - y dx) / (rho^2 + eps^2)`` stays bounded, and the gradient exists
  everywhere. With eps = 1 cm, w > 0.96 once rho > 5 cm.

Gradient in actuated coordinates, with ``J_S, J_E, J_W`` the linear Jacobians of the joint
centres, ``J_ci = J_i,lin + J_i,ang x (R_i c_i)`` those of the links' centres of mass (``c_i``
in the link frame, from the link frames' Jacobians) and ``s = |alpha|_s``::

    d f_g = g sum_i m_i (J_ci[z] - J_S[z])       (shoulder reference; world: without J_S)
    d f_e = 1/2 (pi - s)^2 w dk  -  k (pi - s) s'(alpha) w dalpha  +  1/2 k (pi - s)^2 dw

One kernel, :func:`wholebody.kernels.objectives.arm_energy`, computes both, in the compiled
control step and for :meth:`ArmPotentialEnergy.evaluate`; only a stiffness model of your own
(not a constant nor a :class:`~wholebody.arm.network.NetworkStiffness`) is evaluated in
Python, before each call.

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
    AE_CONSTANT,
    AE_DK,
    AE_FADE,
    AE_G,
    AE_GIVEN,
    AE_K,
    AE_LINK0,
    AE_LINKS,
    AE_NET,
    AE_SHOULDER,
    AE_SIDE,
    AE_SMOOTH,
    AE_WIDTH,
    AF_BASE,
    AF_SHOULDER,
    AF_WRIST,
    ARM_PARTS,
    LINK_WIDTH,
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
        ``delta`` of the smoothed ``|alpha|`` (rad).
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
        upper, fore = arm.upper_arm_bodies[1:], arm.forearm_bodies[1:]
        self._links = (arm.upper_arm, *upper, arm.forearm, *fore)
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
        table = _FrameTable()  # the frames evaluate() reads, as the kernel's ints name them
        self._rows = self._frame_rows(table)
        self._frames = tuple(table.frames)

    @property
    def links(self) -> tuple[Body, ...]:
        """The links whose gravity the energy sums, each with its mass and centre of mass in
        its link frame: the upper arm's, then the forearm's (a segment may span several,
        ``forearm = ["a", "b"]`` in robot.toml)."""
        return self._links

    @property
    def smoothing(self) -> float:
        """``delta`` of the smoothed ``|alpha|`` (rad)."""
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
        """The kernel's parameter block (:mod:`wholebody.kernels.objectives`): ``AE_*``
        parameters, ``ARM_PARTS`` outputs, each link's mass and centre of mass (kg, m in the
        link frame) from ``AE_LINK0``, then the packed stiffness network if the kernels
        evaluate it."""
        links = self.links
        par = np.zeros(AE_LINK0 + LINK_WIDTH * len(links))
        par[AE_G], par[AE_SIDE], par[AE_FADE] = self.g, self.side, self.fade
        par[AE_SMOOTH], par[AE_SHOULDER] = self.smoothing, self.reference == "shoulder"
        par[AE_LINKS] = len(links)
        for i, body in enumerate(links):
            o = AE_LINK0 + LINK_WIDTH * i
            par[o], par[o + 1 : o + 4] = body.mass, body.com
        net = self.network()
        stiffness = self._stiffness
        if type(stiffness) is ConstantStiffness:  # k does not depend on the wrist
            par[AE_K], par[AE_NET] = stiffness.k, AE_CONSTANT
        elif net is not None:
            par[AE_NET] = par.size
        else:  # evaluated in Python before each call (_energy)
            par[AE_NET] = AE_GIVEN
        return par if net is None else np.concatenate([par, net])

    def _frame_rows(self, packer: Packer) -> np.ndarray:
        """The kernel's ints (``AF_*``): the rows ``packer`` gives the shoulder, elbow and
        wrist centres, the base (-1 with a constant stiffness: not read) and each link's
        frame (the order of :attr:`links`)."""
        arm = self.arm
        rows = [packer.frame(f) for f in (arm.shoulder, arm.elbow, arm.wrist)]
        constant = self._params[AE_NET] == AE_CONSTANT
        rows.append(-1 if constant else packer.frame(self.robot.base_frame))
        rows += [packer.frame(body.frame) for body in self.links]
        return np.array(rows, dtype=np.int64)

    def jacobian_frames(self) -> tuple[Frame, ...]:
        """Shoulder, elbow and wrist frames, the base frame when the stiffness depends on the
        wrist position, and the links' frames (each once)."""
        return self._frames

    def network(self) -> np.ndarray | None:
        """The stiffness as a packed network the kernels evaluate themselves, or None (a
        constant, or a model evaluated in Python)."""
        packed = getattr(self._stiffness, "packed", None)
        return packed() if callable(packed) else None

    def pack(self, packer: Packer) -> Packed | None:
        """Compiled wherever the kernels evaluate the stiffness: a constant or a packed
        network, whatever the number of links (a model of your own runs in Python)."""
        if self._params[AE_NET] == AE_GIVEN or not self.compiled_as(
            ArmPotentialEnergy, "evaluate", "_energy"
        ):
            return None
        return Packed(KIND_ARM, self._params, self._frame_rows(packer))

    def evaluate(self, state: RobotState) -> ArmEnergyValue:
        grad = np.empty(self.robot.nu)
        parts = self._energy(state, state.jacobians(self._frames), grad)
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

    def _energy(self, state: RobotState, J: np.ndarray, grad: np.ndarray) -> np.ndarray:
        """``ARM_PARTS`` at ``state`` (the kernel's), the gradient into ``grad`` (``J``: the
        Jacobians of :meth:`jacobian_frames`, one column per entry of ``grad``; none: no
        gradient)."""
        frames, rows = self._frames, self._rows
        P = np.empty((len(frames), 3))
        R = np.empty((len(frames), 3, 3))
        for i, f in enumerate(frames):
            R[i], P[i] = state.rotation_translation(f)
        par = self._params
        if par[AE_NET] == AE_GIVEN:  # a model evaluated here, at Mirror R_b^T (W - S)
            s, w, b = rows[AF_SHOULDER], rows[AF_WRIST], rows[AF_BASE]
            wrist = self._mirror * R[b].T.dot(P[w] - P[s])
            par[AE_K], par[AE_DK : AE_DK + 3] = self._stiffness.evaluate(wrist)
        arm_energy(P, R, J, rows, par, grad)
        return par[AE_WIDTH : AE_WIDTH + ARM_PARTS].copy()

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


class _FrameTable:
    """A :class:`Packer` of the frames :meth:`ArmPotentialEnergy.evaluate` reads: each frame
    asked for gets the next row, once."""

    def __init__(self) -> None:
        self.frames: list[Frame] = []
        self._rows: dict[int, int] = {}  # a frame's index -> its row

    def frame(self, frame: Frame) -> int:
        row = self._rows.setdefault(frame.index, len(self.frames))
        if row == len(self.frames):
            self.frames.append(frame)
        return row


_NO_JACOBIAN = np.zeros((0, 6, 0))  # parts(): the gradient has no columns (J is not read)
_NO_JACOBIAN.setflags(write=False)  # (as the states' Jacobians: one compiled signature)
_NO_GRADIENT = np.zeros(0)
