"""The paper's baseline: support vector regression (RBF kernel, scikit-learn).

Inputs and labels are standardised with the training set's mean and standard deviation;
``epsilon`` is therefore in units of the label's standard deviation and ``gamma`` in
1/(standardised input)^2. :func:`select_svr` picks ``C`` and ``gamma`` by grouped
cross-validation on the training participants only (each fold holds out whole participants),
so the held-out participants never influence the baseline either.

Requires the ``learn`` extra (``scikit-learn``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from wholebody.errors import DataError, SolverError
from wholebody.humanlike.evaluation import regression_scores

__all__ = ["SVR_GRID", "SVRBaseline", "fit_svr", "select_svr"]

SVR_GRID = {"C": (0.3, 1.0, 3.0, 10.0), "gamma": (0.3, 1.0, 3.0)}


def _sklearn():
    try:
        from sklearn.model_selection import GroupKFold
        from sklearn.svm import SVR
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise SolverError(
            "the SVR baseline needs scikit-learn: pip install '.[learn]' from the checkout"
        ) from exc
    return SVR, GroupKFold


@dataclass
class SVRBaseline:
    """A fitted SVR with its standardisation; ``predict`` returns N m/rad."""

    model: object
    x_mean: np.ndarray
    x_scale: np.ndarray
    k_mean: float
    k_scale: float
    params: dict

    def predict(self, X: np.ndarray) -> np.ndarray:
        z = (np.asarray(X, dtype=float) - self.x_mean) / self.x_scale
        return self.k_mean + self.k_scale * self.model.predict(z)  # type: ignore[attr-defined]


def fit_svr(
    X: np.ndarray, y: np.ndarray, *, C: float = 1.0, gamma: float = 1.0, epsilon: float = 0.1
) -> SVRBaseline:
    """Fit an RBF SVR to canonical wrist positions (N, 3) and stiffness (N,)."""
    SVR, _ = _sklearn()
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    xm, xs = X.mean(0), X.std(0)
    xs = np.where(xs > 0, xs, 1.0)
    km, ks = float(y.mean()), float(y.std()) or 1.0
    m = SVR(kernel="rbf", C=C, gamma=gamma, epsilon=epsilon)
    m.fit((X - xm) / xs, (y - km) / ks)
    return SVRBaseline(m, xm, xs, km, ks, {"C": C, "gamma": gamma, "epsilon": epsilon})


def select_svr(
    X: np.ndarray,
    y: np.ndarray,
    groups: Sequence[str],
    *,
    grid: dict[str, Iterable[float]] | None = None,
    n_splits: int = 3,
    epsilon: float = 0.1,
    progress: bool = False,
) -> tuple[dict, list[dict]]:
    """Grouped cross-validation over ``grid`` (``C`` x ``gamma``; ``min(n_splits, groups)``
    folds); returns the parameters with the lowest mean validation MSE and the table of all
    candidates."""
    _, GroupKFold = _sklearn()
    grid = grid or SVR_GRID
    cands = [
        {"C": float(c), "gamma": float(g), "epsilon": epsilon}
        for c in grid["C"]
        for g in grid["gamma"]
    ]
    n_groups = len(set(np.asarray(groups).tolist()))
    if n_groups < 2:
        raise DataError(f"select_svr: grouped cross-validation needs >= 2 groups, got {n_groups}")
    folds = list(GroupKFold(n_splits=min(n_splits, n_groups)).split(X, y, np.asarray(groups)))
    it = cands
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(cands, desc="SVR grid search", unit="candidate")
    table = []
    for c in it:
        mses = []
        for tr, va in folds:
            m = fit_svr(X[tr], y[tr], **c)
            mses.append(regression_scores(y[va], m.predict(X[va]))["mse"])
        table.append({**c, "cv_mse": float(np.mean(mses))})
    best = min(table, key=lambda r: r["cv_mse"])
    return {k: best[k] for k in ("C", "gamma", "epsilon")}, table
