"""The linear baseline of the stiffness network: ``k = c + w . p`` by least squares.

``p`` is the canonical wrist position (m, :mod:`wholebody.humanlike.dataset`) and ``k`` the
stiffness (N m/rad). The network is worth its weights only where it predicts new people's
``k`` better than this (issue 37): the stiffness card and ``benchmarks/stiffness_baselines.py``
score both on the same held-out records.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LinearBaseline", "fit_linear"]


@dataclass(frozen=True)
class LinearBaseline:
    """``k = intercept + coef . p`` (N m/rad; ``coef`` in N m/rad per m)."""

    intercept: float
    coef: np.ndarray

    def predict(self, X: np.ndarray) -> np.ndarray:
        """``k`` at the canonical wrist positions ``X`` (N, 3), m."""
        return self.intercept + np.asarray(X, dtype=float) @ self.coef


def fit_linear(X: np.ndarray, y: np.ndarray) -> LinearBaseline:
    """The least-squares fit of ``y`` (N,) on ``[1, X]`` (``X``: N x 3)."""
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    A = np.column_stack([np.ones(len(X)), X])
    solution, *_ = np.linalg.lstsq(A, y, rcond=None)
    return LinearBaseline(float(solution[0]), solution[1:])
