"""Scores of a stiffness regressor on held-out records (numpy only)."""

from __future__ import annotations

import numpy as np

from wholebody.errors import DataError

__all__ = ["regression_scores"]


def regression_scores(y: np.ndarray, y_pred: np.ndarray) -> dict[str, float]:
    """``r2`` (coefficient of determination, 1 - SS_res / SS_tot about the mean of ``y``),
    ``mse`` (mean squared error, (N m/rad)^2 for stiffness), ``rmse`` and ``n``."""
    y = np.asarray(y, dtype=float).reshape(-1)
    y_pred = np.asarray(y_pred, dtype=float).reshape(-1)
    if y.shape != y_pred.shape or len(y) < 2:
        raise DataError(f"regression_scores: need two equal arrays of >= 2 values, got "
                        f"{y.shape} and {y_pred.shape}")  # fmt: skip
    res = float(np.sum((y - y_pred) ** 2))
    tot = float(np.sum((y - y.mean()) ** 2))
    mse = res / len(y)
    return {"r2": 1.0 - res / tot if tot > 0 else float("nan"), "mse": mse,
            "rmse": float(np.sqrt(mse)), "n": len(y)}  # fmt: skip
