"""Stiffness models ``k(wrist)`` of the virtual torsion spring.

The spring energy of an arm is ``1/2 k (pi - alpha)^2`` (NOTES §2). Its stiffness is either a
constant or a model of the wrist position learned from people (:mod:`wholebody.humanlike`
network). A model's input is the **wrist position relative to the shoulder** (m) in the
arm's canonical body axes:

* x forward (the robot's base x axis),
* y **medial**, towards the other arm (the base's +y for a right arm, -y for a left arm),
* z up.

so one model serves both arms of a mirrored robot. It returns ``k`` (N m/rad) and
``dk/dwrist`` (N m/rad per m), which the arm-energy objective chains into its gradient.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from wholebody.errors import DimensionError

__all__ = ["ConstantStiffness", "StiffnessModel"]


class StiffnessModel(ABC):
    """``k(p)`` with its gradient; ``p`` = canonical wrist position (see module docstring)."""

    @abstractmethod
    def evaluate(self, wrist: np.ndarray) -> tuple[float, np.ndarray]:
        """Stiffness (N m/rad) and its gradient (3,) at one canonical wrist position (m)."""


class ConstantStiffness(StiffnessModel):
    """A stiffness that does not depend on the wrist position."""

    def __init__(self, k: float) -> None:
        if not np.isfinite(k) or k < 0:
            raise DimensionError(f"stiffness must be a finite number >= 0 N m/rad, got {k}")
        self._k = float(k)
        self._zero = np.zeros(3)
        self._zero.setflags(write=False)

    @property
    def k(self) -> float:
        """The stiffness (N m/rad), fixed at construction (an arm energy copies it)."""
        return self._k

    def evaluate(self, wrist: np.ndarray) -> tuple[float, np.ndarray]:
        return self.k, self._zero

    def __repr__(self) -> str:
        return f"ConstantStiffness({self.k:g})"
