"""Human-to-robot posture mapping (Niu et al. 2024, Section 2, Figure 5) and the canonical
arm axes.

Posture mapping
---------------
The directions of the human upper arm ``S->E`` and forearm ``E->W`` are kept and their
lengths replaced by the robot's upper-arm and forearm lengths ``L1``, ``L2``::

    E_R = S + L1 (E - S) / |E - S|
    W_R = E_R + L2 (W - E) / |W - E|

so the robot's elbow flexion and the plane of its arm equal the person's, while its wrist
moves (the ratio ``L1 / L2`` differs), and with it the shoulder-wrist line and the arm angle.

Canonical arm axes
------------------
A stiffness model's input is the wrist relative to the shoulder in the arm's canonical body
axes (see :mod:`wholebody.arm.stiffness`): x forward, y **medial** (towards the other
arm), z up. From the recordings' lab frame (+x participant's right, +y forward, +z up)::

    right arm: (x, y, z)_canonical = ( y_lab, -x_lab, z_lab)    (a rotation)
    left arm:  (x, y, z)_canonical = ( y_lab,  x_lab, z_lab)    (a mirror image)

In canonical axes every arm looks like a right arm seen in a frame with x forward, y to the
left, z up (the robot's base frame for its right arm), so its arm angle is
``arm_angle(S, E, W, side=CANONICAL_SIDE)`` with ``CANONICAL_SIDE = -1``; it equals the arm
angle of the original arm in the lab frame with its own side.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from wholebody.errors import DataError, DimensionError
from wholebody.robot import ArmChain, Robot

__all__ = [
    "CANONICAL_SIDE",
    "ArmParameters",
    "canonical_to_lab",
    "lab_to_canonical",
    "map_to_robot",
]

CANONICAL_SIDE = -1.0
COM_OFF_AXIS_TOLERANCE = 1e-3  # m


@dataclass(frozen=True)
class ArmParameters:
    """Lengths, masses and centre-of-mass fractions of a robot arm (hand excluded).

    Attributes
    ----------
    upper_arm, forearm
        Shoulder-elbow and elbow-wrist distances (m).
    upper_arm_mass, forearm_mass
        ``m1``, ``m2`` (kg).
    upper_arm_com, forearm_com
        ``c1``, ``c2``: centre of mass as a fraction of the segment from its proximal joint
        (the projection of the model's centre of mass on the segment).
    gravity
        ``g`` (m/s^2), the norm of the model's gravity.
    robot
        Name of the robot the numbers come from (or a free label).
    """

    upper_arm: float
    forearm: float
    upper_arm_mass: float
    forearm_mass: float
    upper_arm_com: float
    forearm_com: float
    gravity: float = 9.81
    robot: str = ""

    def __post_init__(self) -> None:
        vals = asdict(self)
        vals.pop("robot")
        for k, v in vals.items():
            if not np.isfinite(v) or v <= 0:
                raise DimensionError(f"ArmParameters.{k} must be a finite number > 0, got {v}")

    @property
    def lever(self) -> float:
        """``g (m1 c1 + m2 (1 - c2))`` (N): the gravity moment per metre of elbow height.

        Raising the elbow by ``dh`` at fixed shoulder and wrist raises the upper-arm centre
        of mass by ``c1 dh`` and the forearm's by ``(1 - c2) dh``.
        """
        m1, m2 = self.upper_arm_mass, self.forearm_mass
        return self.gravity * (m1 * self.upper_arm_com + m2 * (1.0 - self.forearm_com))

    @classmethod
    def from_robot(cls, robot: Robot, arm: str | ArmChain = "right") -> ArmParameters:
        """Read them from the robot model at its home posture.

        ``c1 = (C1 - S).(E - S) / L1^2`` and ``c2 = (C2 - E).(W - E) / L2^2`` with ``C1``,
        ``C2`` the model's centres of mass of the upper-arm and forearm bodies. The closed
        form label (:mod:`wholebody.humanlike.labels`) assumes they lie on the segment axes;
        a centre of mass more than 1 mm off its axis raises.
        """
        chain = arm if isinstance(arm, ArmChain) else robot.arm(arm)
        state = robot.update(robot.home())
        S, E, W = (state.position(f) for f in (chain.shoulder, chain.elbow, chain.wrist))
        fractions, masses = [], []
        for bodies, a, b in ((chain.upper_arm_bodies, S, E), (chain.forearm_bodies, E, W)):
            seg = b - a
            mass = sum(body.mass for body in bodies)  # a segment split over several links
            c = sum(body.mass * state.com_position(body) for body in bodies) / mass - a
            body = bodies[0]
            frac = float(c @ seg / (seg @ seg))
            off = float(np.linalg.norm(c - frac * seg))
            if off > COM_OFF_AXIS_TOLERANCE:
                raise DataError(
                    f"{robot.name}: the centre of mass of {body.name!r} is {off * 1000:.1f} mm "
                    "off its segment axis; the closed-form stiffness label needs it on the axis"
                )
            fractions.append(frac)
            masses.append(mass)
        return cls(
            chain.upper_arm_length,
            chain.forearm_length,
            masses[0],
            masses[1],
            fractions[0],
            fractions[1],
            float(np.linalg.norm(robot.model.gravity.linear)),
            robot.name,
        )


def map_to_robot(
    S: np.ndarray, E: np.ndarray, W: np.ndarray, upper_arm: float, forearm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Robot elbow and wrist (m) for a human posture, any leading shape ``(..., 3)``.

    Keeps the directions of ``S->E`` and ``E->W`` and sets their lengths to ``upper_arm``
    and ``forearm`` (m); the shoulder stays at ``S``. Returns ``(E_R, W_R)``.
    """
    S, E, W = (np.asarray(v, dtype=float) for v in (S, E, W))
    a, b = E - S, W - E
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    if np.any(na == 0) or np.any(nb == 0):
        raise DimensionError("map_to_robot: coincident shoulder/elbow or elbow/wrist")
    E_R = S + a * (upper_arm / na)
    return E_R, E_R + b * (forearm / nb)


def lab_to_canonical(v: np.ndarray, side: str) -> np.ndarray:
    """Vectors (..., 3) from the recordings' lab axes to the canonical arm axes of ``side``
    (``"R"``/``"L"``): x forward, y medial, z up (see the module docstring)."""
    v = np.asarray(v, dtype=float)
    if side == "R":
        return np.stack([v[..., 1], -v[..., 0], v[..., 2]], axis=-1)
    if side == "L":
        return np.stack([v[..., 1], v[..., 0], v[..., 2]], axis=-1)
    raise DimensionError(f"side must be 'R' or 'L', got {side!r}")


def canonical_to_lab(v: np.ndarray, side: str) -> np.ndarray:
    """The inverse of :func:`lab_to_canonical`."""
    v = np.asarray(v, dtype=float)
    if side == "R":
        return np.stack([-v[..., 1], v[..., 0], v[..., 2]], axis=-1)
    if side == "L":
        return np.stack([v[..., 1], v[..., 0], v[..., 2]], axis=-1)
    raise DimensionError(f"side must be 'R' or 'L', got {side!r}")
