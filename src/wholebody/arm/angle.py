"""The arm angle: rotation of the arm plane about the shoulder-wrist line.

Definition (NOTES §2, decided here): with shoulder S, elbow E, wrist W, ``u`` the unit vector
from S to W and ``g = (0, 0, -1)`` the downward vertical, the arm angle ``alpha`` is the angle,
about ``u``, from the downward reference ``r = g - (g.u) u`` to the elbow's offset
``d = (E - S) - ((E - S).u) u`` from the S-W line. ``alpha = 0`` when the elbow hangs at its
lowest point on its circle, ``alpha = pi`` at its highest, and ``alpha > 0`` when the elbow
swings **outwards** (laterally). The two arms are mirrored: ``side = +1`` for a left arm,
``-1`` for a right arm, so mirrored postures have equal angles.

In closed form, with ``a = E - S``::

    x = g.d = g.a - (a.u)(g.u)            (= |d| |r| cos alpha)
    y = side * (u x g).a                  (= |d| |r| sin alpha)
    alpha = atan2(y, x)  in (-pi, pi]

``rho_perp^2 = x^2 + y^2 = |d|^2 |r|^2`` is zero exactly where alpha is undefined: a straight
arm (E on the S-W line) or a vertical S-W line. Every function here is vectorised over
leading dimensions (arrays of shape (..., 3)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.kernels.objectives import arm_angle_terms

__all__ = ["DOWN", "ArmAngle", "arm_angle", "arm_angle_with_gradient"]

DOWN = np.array([0.0, 0.0, -1.0])


def _components(S: np.ndarray, E: np.ndarray, W: np.ndarray, side: float):
    a = E - S
    c = W - S
    L = np.linalg.norm(c, axis=-1, keepdims=True)
    u = c / L
    gu = u[..., 2:3] * DOWN[2]  # g.u
    au = np.sum(a * u, axis=-1, keepdims=True)
    x = a[..., 2] * DOWN[2] - (au * gu)[..., 0]
    ug = np.cross(u, DOWN)
    y = side * np.sum(ug * a, axis=-1)
    return a, c, L, u, gu, au, ug, x, y


def arm_angle(S: np.ndarray, E: np.ndarray, W: np.ndarray, side: float) -> np.ndarray:
    """Arm angle (rad, in (-pi, pi]) of shoulder/elbow/wrist positions (m), any leading shape.

    ``side`` is +1 for a left arm, -1 for a right arm.
    """
    *_, x, y = _components(np.asarray(S, float), np.asarray(E, float), np.asarray(W, float), side)
    return np.arctan2(y, x)


@dataclass(frozen=True)
class ArmAngle:
    """Arm angle and the quantities its smooth uses need, with gradients in S, E, W.

    ``dx_dS`` etc. are the gradients of the components ``x`` and ``y`` (see the module
    docstring) with respect to the three positions; ``alpha``'s own gradient is
    ``(x dy - y dx) / (x^2 + y^2)``, available as :meth:`alpha_gradient` where it exists.
    """

    alpha: float
    x: float
    y: float
    dx: np.ndarray  # (3, 3): rows d/dS, d/dE, d/dW
    dy: np.ndarray  # (3, 3)

    @property
    def rho2(self) -> float:
        """``x^2 + y^2 = |d|^2 sin^2(theta_u)`` (m^2): zero where alpha is undefined."""
        return self.x * self.x + self.y * self.y

    def alpha_gradient(self) -> np.ndarray:
        """(3, 3): d alpha / dS, dE, dW (rad/m). Undefined (inf) where ``rho2 == 0``."""
        return (self.x * self.dy - self.y * self.dx) / self.rho2


def arm_angle_with_gradient(S: np.ndarray, E: np.ndarray, W: np.ndarray, side: float) -> ArmAngle:
    """Arm angle of one arm (positions (3,)) with the gradients of its components.

    With ``g = (0, 0, -1)``, ``u x g = (-u_y, u_x, 0)`` and ``g x a = (a_y, -a_x, 0)``, so::

        x = -a_z + (a.u) u_z                  y = side (u_x a_y - u_y a_x)
        dx/da = g + u_z u                     dy/da = side (-u_y, u_x, 0)
        dx/du = u_z a + (a.u) e_z             dy/du = side (a_y, -a_x, 0)
        d/dS = -d/da - P d/du,   d/dE = d/da,   d/dW = P d/du,   P = (I - u u^T) / |W - S|

    (evaluated by the kernel :func:`wholebody.kernels.objectives.arm_angle_terms`, which the
    arm energy runs in the control loop).
    """
    dx, dy = np.empty(9), np.empty(9)
    alpha, x, y = arm_angle_terms(
        np.array(S, dtype=float),
        np.array(E, dtype=float),
        np.array(W, dtype=float),
        float(side),
        dx,
        dy,
    )
    return ArmAngle(float(alpha), float(x), float(y), dx.reshape(3, 3), dy.reshape(3, 3))
