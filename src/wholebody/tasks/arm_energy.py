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
  with the arm angle alpha (:mod:`wholebody.humanlike.arm_geometry`, 0 = elbow lowest), rest
  angle pi, and stiffness k constant or a model ``k(wrist)``
  (:class:`~wholebody.humanlike.stiffness.StiffnessModel`).

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

The stiffness model's input is the wrist relative to the shoulder in the arm's canonical body
axes (x forward, y medial, z up; see :mod:`wholebody.humanlike.stiffness`):
``p = Mirror R_b^T (W - S)`` with ``R_b`` the base yaw, so
``dp = Mirror R_b^T (J_W - J_S + [W - S]x J_b,ang)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wholebody.errors import DimensionError
from wholebody.humanlike.arm_geometry import arm_angle_terms
from wholebody.humanlike.stiffness import ConstantStiffness, StiffnessModel
from wholebody.robot import ArmChain, Frame, Robot, RobotState
from wholebody.tasks.base import Objective, ObjectiveValue

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
        self.name = name or f"{self.arm.name}_arm_energy"
        self.weight = float(weight)
        if isinstance(stiffness, StiffnessModel):
            self.stiffness = stiffness
        else:
            try:  # a number, a numpy scalar or 0-d array; not a string such as "learned"
                k = float(stiffness) if not isinstance(stiffness, str) else None
            except (TypeError, ValueError):
                k = None
            if k is None:
                raise DimensionError(
                    f"{self.name}: stiffness must be a number (N m/rad) or a StiffnessModel "
                    "(the learned one: wholebody.humanlike.default_stiffness(robot)), got "
                    f"{stiffness!r}"
                )
            self.stiffness = ConstantStiffness(k)
        if not smoothing > 0 or not fade > 0:
            raise DimensionError(f"{self.name}: smoothing and fade must be > 0")
        self.smoothing, self.fade = float(smoothing), float(fade)
        if reference not in ("shoulder", "world"):
            raise DimensionError(f"{self.name}: reference must be 'shoulder' or 'world', "
                                 f"got {reference!r}")  # fmt: skip
        self.reference = reference
        self.side = 1.0 if self.arm.side == "left" else -1.0
        self.g = float(np.linalg.norm(robot.model.gravity.linear))
        self._mirror = np.array([1.0, -self.side, 1.0])  # canonical y = medial
        self._constant = isinstance(self.stiffness, ConstantStiffness)
        arm = self.arm
        self._frames = (arm.shoulder, arm.elbow, arm.wrist, arm.upper_arm.frame,
                        arm.forearm.frame)  # fmt: skip
        self._frames_base = (*self._frames, robot.base_frame)
        # (body, mass, offset of its rows in C, centre of mass as floats) per arm body
        self._bodies = tuple((body, body.mass, o, tuple(body.com.tolist()))
                             for body, o in ((arm.upper_arm, 18), (arm.forearm, 24)))  # fmt: skip

    def jacobian_frames(self) -> tuple[Frame, ...]:
        """Shoulder, elbow, wrist, upper-arm and forearm frames, and the base frame when the
        stiffness depends on the wrist position."""
        return self._frames if self._constant else self._frames_base

    def evaluate(self, state: RobotState) -> ArmEnergyValue:
        # Plain floats for the 3-vectors; the gradient is one product of a coefficient row
        # with the stacked Jacobians of (shoulder, elbow, wrist, upper arm, forearm, base).
        arm, g = self.arm, self.g
        m1, m2 = arm.upper_arm.mass, arm.forearm.mass
        S = state.rotation_translation(arm.shoulder)[1].tolist()
        E = state.rotation_translation(arm.elbow)[1].tolist()
        W = state.rotation_translation(arm.wrist)[1].tolist()
        C = [0.0] * 36  # coefficients of the 6 rows of each frame, in jacobian_frames() order
        # Gravity: only the z rows of the centre-of-mass Jacobians are needed,
        # v_com,z = v_o,z + w_x r_y - w_y r_x with r the body-frame-to-com offset.
        gravity = 0.0
        for body, m, o, (c0, c1, c2) in self._bodies:
            R, p = state.rotation_translation(body.frame)
            r0, r1, r2 = R.tolist()
            rx = r0[0] * c0 + r0[1] * c1 + r0[2] * c2
            ry = r1[0] * c0 + r1[1] * c1 + r1[2] * c2
            rz = r2[0] * c0 + r2[1] * c1 + r2[2] * c2
            gm = g * m
            gravity += gm * (float(p[2]) + rz)
            C[o + 2] += gm
            C[o + 3] += gm * ry
            C[o + 4] -= gm * rx
        if self.reference == "shoulder":
            gravity -= g * (m1 + m2) * S[2]
            C[2] -= g * (m1 + m2)

        alpha, x, y, dx, dy = arm_angle_terms(S, E, W, self.side)
        rho2, eps2 = x * x + y * y, self.fade**2
        w = rho2 / (rho2 + eps2)
        delta = self.smoothing
        if abs(alpha) < delta:
            s, ds = alpha * alpha / (2 * delta) + delta / 2, alpha / delta
        else:
            s, ds = abs(alpha), (alpha > 0) - (alpha < 0)
        rest = math.pi - s
        stiffness = self.stiffness
        if type(stiffness) is ConstantStiffness:  # k does not depend on the wrist
            k, dk_dp = stiffness.k, None
        else:
            Rb = state.rotation(self.robot.base_frame)
            r = np.array([W[0] - S[0], W[1] - S[1], W[2] - S[2]])
            k, dk_dp = stiffness.evaluate(self._mirror * Rb.T.dot(r))
            if self._constant:
                dk_dp = None
        spring = 0.5 * k * rest * rest * w
        # d f_e = k rest (1/2 rest dw - s' w dalpha): a combination of dx and dy, with
        # dw = 2 eps^2 (x dx + y dy) / (rho^2 + eps^2)^2, w dalpha = (x dy - y dx)/(rho^2+eps^2)
        den = rho2 + eps2
        cw = k * rest * 0.5 * rest * 2 * eps2 / (den * den)
        ca = -k * rest * ds / den
        coef_x = cw * x - ca * y
        coef_y = cw * y + ca * x
        for i, o in enumerate((0, 1, 2, 6, 7, 8, 12, 13, 14)):  # d f_e / d(S, E, W)
            C[o] += coef_x * dx[i] + coef_y * dy[i]
        if dk_dp is not None:
            # dp = Mirror R_b^T (J_W - J_S + [W - S]x J_b,ang): with q = (c dk_dp Mirror) R_b^T,
            # q.dp = q.J_W - q.J_S + (q x (W - S)).J_b,ang
            q0, q1, q2 = ((0.5 * rest * rest * w) * (dk_dp * self._mirror)).dot(Rb.T).tolist()
            d0, d1, d2 = r.tolist()
            for i, qi in enumerate((q0, q1, q2)):
                C[12 + i] += qi
                C[i] -= qi
            C[33] += q1 * d2 - q2 * d1
            C[34] += q2 * d0 - q0 * d2
            C[35] += q0 * d1 - q1 * d0
            J = state.jacobians(self._frames_base)
            grad = np.array(C).dot(J.reshape(36, -1))
        else:
            J = state.jacobians(self._frames)
            grad = np.array(C[:30]).dot(J.reshape(30, -1))
        return ArmEnergyValue(value=gravity + spring, gradient=grad, gravity=gravity,
                              spring=spring, arm_angle=alpha, stiffness=k,
                              rho=math.sqrt(rho2))  # fmt: skip
