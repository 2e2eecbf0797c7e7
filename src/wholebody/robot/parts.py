"""The named parts of a robot that tasks refer to: frames, bodies, joint groups and arms.

Each is a small frozen handle resolved once by name (:meth:`Robot.frame
<wholebody.robot.Robot.frame>`, :meth:`~wholebody.robot.Robot.body`,
:meth:`~wholebody.robot.Robot.group`, :meth:`~wholebody.robot.Robot.arm`), so that the
control loop reads the model by index, never by string.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ArmChain", "Body", "Frame", "JointGroup"]


@dataclass(frozen=True)
class Frame:
    """A frame of the robot model, resolved once by name (see :meth:`Robot.frame`): its
    index among Pinocchio's frames and the index of the joint that moves it."""

    name: str
    index: int
    joint: int

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True)
class Body:
    """A rigid link with mass: its frame, mass (kg) and centre of mass in the link frame (m)."""

    name: str
    frame: Frame
    mass: float
    com: np.ndarray


@dataclass(frozen=True)
class JointGroup:
    """Named joints and their indices into the actuated velocity ``u``."""

    name: str
    joints: tuple[str, ...]
    indices: np.ndarray

    def __len__(self) -> int:
        return len(self.joints)


@dataclass(frozen=True)
class ArmChain:
    """An arm: frames at the shoulder, elbow and wrist centres and the tool, the upper-arm
    and forearm bodies, its side (``"left"``/``"right"``, which mirrors the arm angle) and
    its joint group if one is named in ``robot.toml``."""

    name: str
    side: str
    shoulder: Frame
    elbow: Frame
    wrist: Frame
    tool: Frame
    upper_arm: Body
    forearm: Body
    group: JointGroup | None

    upper_arm_bodies: tuple[Body, ...] = ()
    """Every link of the upper-arm segment (``upper_arm`` is the first): a segment's mass may
    be split over several links; the arm energy adds them all."""
    forearm_bodies: tuple[Body, ...] = ()
    """Every link of the forearm segment (``forearm`` is the first)."""

    @property
    def upper_arm_length(self) -> float:
        """Shoulder-to-elbow distance (m), the same at every posture (checked on loading)."""
        return float(self._lengths[0])

    @property
    def forearm_length(self) -> float:
        """Elbow-to-wrist distance (m)."""
        return float(self._lengths[1])

    _lengths: tuple[float, float] = (0.0, 0.0)
