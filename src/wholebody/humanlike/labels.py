"""Stiffness labels from postures: the principle of minimum total potential energy.

The arm's potential energy (NOTES §2; :class:`~wholebody.tasks.arm_energy.ArmPotentialEnergy`)
is ``f_p = f_g + f_e`` with gravity ``f_g = g (m1 h1 + m2 h2)`` (heights of the upper-arm
and forearm centres of mass) and the virtual torsion spring ``f_e = 1/2 k (pi - |alpha|)^2``.
An observed posture is taken as an equilibrium under a rotation of the elbow about the
shoulder-wrist line at fixed S and W (the arm angle alpha), ``d f_p / d alpha = 0``::

    d f_g/d alpha - k (pi - |alpha|) sign(alpha) = 0
    =>  k = (d f_g / d alpha) sign(alpha) / (pi - |alpha|)

Closed form
-----------
With ``u`` the unit S-W direction, ``d`` the elbow's offset from the S-W line (``|d| = rho``)
and ``theta`` the angle of S-W from the vertical, rotating the elbow by alpha about ``u``
changes its height by ``-rho sin(theta) cos(alpha)`` (alpha = 0 lowest), so with the centres
of mass at fractions ``c1``, ``c2`` of their segments (from the proximal joint)::

    f_g(alpha) = const - A cos(alpha),    A = g (m1 c1 + m2 (1 - c2)) rho sin(theta)
    k = A sin|alpha| / (pi - |alpha|)     (N m/rad; >= 0 for every alpha in (-pi, pi])

``rho sin(theta) = sqrt(x^2 + y^2)`` in the notation of
:mod:`~wholebody.arm.angle`. **Negative alpha** (elbow tucked in past its lowest
point): the spring acts on ``|alpha|``, so the same formula holds with ``|alpha|`` and the
label is an even function of alpha: the gravity moment ``A sin(alpha)`` pulls the elbow
back towards alpha = 0 from either side and the spring, wound towards pi through |alpha|,
balances it. (The objective smooths ``|alpha|`` within ``delta`` = 0.05 rad of zero; the
labels use the exact magnitude.)

Ill-conditioned frames (dropped when building the dataset, see :func:`frame_rules`)
-----------------------------------------------------------------------------------
* ``straight``: the robot's elbow is less than :data:`MIN_ELBOW_OFFSET` (4 cm; about 8.6 deg
  between upper arm and S-W for this robot) from the S-W line. alpha is undefined for a
  straight arm, and its measurement error grows as (marker error) / rho.
* ``vertical``: the S-W line is within :data:`MIN_TILT` (20 deg) of the vertical. The
  downward reference of alpha is undefined there and ``A -> 0``.
* ``forearm``: the person's measured forearm length differs from its median over the trial
  by more than :data:`MAX_FOREARM_DEVIATION` (2 cm): soft-tissue artefact moved the elbow or
  wrist estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.arm.angle import arm_angle
from wholebody.humanlike.mapping import CANONICAL_SIDE, ArmParameters

__all__ = [
    "MAX_FOREARM_DEVIATION",
    "MIN_ELBOW_OFFSET",
    "MIN_TILT",
    "ArmGeometry",
    "StiffnessLabels",
    "arm_geometry",
    "frame_rules",
    "gravity_energy",
    "rotate_elbow",
    "stiffness_labels",
]

MIN_ELBOW_OFFSET = 0.04  # m, robot elbow distance from the S-W line
MIN_TILT = np.radians(20.0)  # rad, angle of S-W from the vertical (either way)
MAX_FOREARM_DEVIATION = 0.02  # m, |forearm length - trial median| of the person


@dataclass(frozen=True)
class ArmGeometry:
    """What the frame rules and the labels need of a posture (arrays of the input's leading
    shape): ``alpha`` the signed arm angle (rad), ``elbow_offset`` ``rho`` the elbow's
    distance from the S-W line (m), ``tilt`` ``theta`` the angle of S-W from the vertical
    (rad in [0, pi]) and ``sin_tilt`` its sine."""

    alpha: np.ndarray
    elbow_offset: np.ndarray
    tilt: np.ndarray
    sin_tilt: np.ndarray


def arm_geometry(
    S: np.ndarray, E: np.ndarray, W: np.ndarray, side: float = CANONICAL_SIDE
) -> ArmGeometry:
    """Arm angle, elbow offset and tilt of postures (..., 3), z up, m (``side`` as in
    :func:`stiffness_labels`). Why: one computation for the labels and the frame rules of
    robot and human postures alike."""
    S, E, W = (np.asarray(v, dtype=float) for v in (S, E, W))
    alpha = arm_angle(S, E, W, side)
    c = W - S
    u = c / np.linalg.norm(c, axis=-1, keepdims=True)
    a = E - S
    d = a - np.sum(a * u, axis=-1, keepdims=True) * u
    sin_t = np.sqrt(np.clip(1.0 - u[..., 2] ** 2, 0.0, 1.0))
    tilt = np.arccos(np.clip(-u[..., 2], -1.0, 1.0))
    return ArmGeometry(alpha, np.linalg.norm(d, axis=-1), tilt, sin_t)


@dataclass(frozen=True)
class StiffnessLabels:
    """Per-frame labels (arrays of the input's leading shape).

    Attributes
    ----------
    k
        Stiffness, N m/rad.
    alpha
        Signed arm angle, rad (0 = elbow lowest, > 0 outward).
    amplitude
        ``A`` (N m): the gravity energy is ``const - A cos(alpha)``.
    elbow_offset
        ``rho``: elbow distance from the S-W line, m.
    tilt
        ``theta``: angle of S-W from the vertical, rad in [0, pi].
    """

    k: np.ndarray
    alpha: np.ndarray
    amplitude: np.ndarray
    elbow_offset: np.ndarray
    tilt: np.ndarray


def gravity_energy(
    S: np.ndarray, E: np.ndarray, W: np.ndarray, params: ArmParameters
) -> np.ndarray:
    """``f_g = g (m1 h1 + m2 h2)`` (J), heights z (m) of the centres of mass
    ``S + c1 (E - S)`` and ``E + c2 (W - E)``; positions (..., 3) with z up."""
    h1 = S[..., 2] + params.upper_arm_com * (E[..., 2] - S[..., 2])
    h2 = E[..., 2] + params.forearm_com * (W[..., 2] - E[..., 2])
    return params.gravity * (params.upper_arm_mass * h1 + params.forearm_mass * h2)


def rotate_elbow(
    S: np.ndarray, E: np.ndarray, W: np.ndarray, angle: float | np.ndarray
) -> np.ndarray:
    """The elbow rotated by ``angle`` (rad, right-handed) about the S-W line (Rodrigues)."""
    u = W - S
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    a = E - S
    ang = np.asarray(angle, dtype=float)[..., None]
    c, s = np.cos(ang), np.sin(ang)
    ua = np.sum(u * a, axis=-1, keepdims=True)
    return S + a * c + np.cross(u, a) * s + u * ua * (1.0 - c)


def stiffness_labels(
    S: np.ndarray,
    E: np.ndarray,
    W: np.ndarray,
    params: ArmParameters,
    side: float = CANONICAL_SIDE,
) -> StiffnessLabels:
    """Closed-form labels (module docstring) of robot postures (..., 3), z up, metres.

    ``side`` is the arm-angle side convention of the positions' frame (-1 for the canonical
    axes and right arms, +1 for a left arm in a frame with y to the left).
    """
    geo = arm_geometry(S, E, W, side)
    A = params.lever * geo.elbow_offset * geo.sin_tilt
    mag = np.abs(geo.alpha)
    k = A * np.sin(mag) / (np.pi - mag)
    return StiffnessLabels(k, geo.alpha, A, geo.elbow_offset, geo.tilt)


def frame_rules(
    labels: StiffnessLabels | ArmGeometry,
    forearm_deviation: np.ndarray | None = None,
    *,
    min_elbow_offset: float = MIN_ELBOW_OFFSET,
    min_tilt: float = MIN_TILT,
    max_forearm_deviation: float = MAX_FOREARM_DEVIATION,
) -> dict[str, np.ndarray]:
    """Boolean masks of the frames each rule drops (module docstring): ``straight``,
    ``vertical`` and, given the person's ``|forearm length - trial median|`` (m),
    ``forearm``. A frame is kept when no mask is set. ``labels``: the labels of robot
    postures, or the :func:`arm_geometry` of any posture (the human arm-angle model's)."""
    sin_t = np.sin(labels.tilt)
    rules = {
        "straight": labels.elbow_offset < min_elbow_offset,
        "vertical": sin_t < np.sin(min_tilt),
    }
    if forearm_deviation is not None:
        rules["forearm"] = np.asarray(forearm_deviation) > max_forearm_deviation
    return rules
