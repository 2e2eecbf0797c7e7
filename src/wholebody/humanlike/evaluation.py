"""Scores of a regressor on held-out records, and their bootstrap intervals (numpy only)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wholebody.errors import DataError

__all__ = ["cluster_bootstrap", "r2_with_intervals", "regression_scores"]


def regression_scores(y: np.ndarray, y_pred: np.ndarray) -> dict[str, float]:
    """``r2`` (coefficient of determination, 1 - SS_res / SS_tot about the mean of ``y``),
    ``mse`` (mean squared error, (N m/rad)^2 for stiffness), ``rmse`` and ``n``."""
    y = np.asarray(y, dtype=float).reshape(-1)
    y_pred = np.asarray(y_pred, dtype=float).reshape(-1)
    if y.shape != y_pred.shape or len(y) < 2:
        raise DataError(
            f"regression_scores: need two equal arrays of >= 2 values, got "
            f"{y.shape} and {y_pred.shape}"
        )
    res = float(np.sum((y - y_pred) ** 2))
    tot = float(np.sum((y - y.mean()) ** 2))
    mse = res / len(y)
    return {
        "r2": 1.0 - res / tot if tot > 0 else float("nan"),
        "mse": mse,
        "rmse": float(np.sqrt(mse)),
        "n": len(y),
    }


def cluster_bootstrap(
    statistic: Callable[[np.ndarray], float],
    clusters: np.ndarray,
    *,
    n_boot: int = 2000,
    seed: int = 0,
    level: float = 0.95,
) -> tuple[float, float, float]:
    """``statistic`` of all records and its percentile interval over resamples of whole
    clusters (for example the trials of one participant), drawn with replacement.

    ``statistic(idx)`` takes an index array into the records; each resample draws as many
    clusters as there are, with replacement, and concatenates their records. Returns
    ``(value, low, high)``, the interval's bounds the ``(1 -+ level) / 2`` percentiles of the
    ``n_boot`` resampled values. Why clusters: frames of one trial are strongly correlated,
    so resampling frames would make the interval far too narrow.
    """
    names, inverse = np.unique(np.asarray(clusters), return_inverse=True)
    if len(names) < 2 or n_boot < 1:
        raise DataError(
            f"cluster_bootstrap: need >= 2 clusters and n_boot >= 1, got {len(names)} and {n_boot}"
        )
    order = np.argsort(inverse, kind="stable")
    members = np.split(order, np.cumsum(np.bincount(inverse))[:-1])
    rng = np.random.default_rng(seed)
    values = np.empty(n_boot)
    for b in range(n_boot):
        pick = rng.integers(0, len(names), len(names))
        values[b] = statistic(np.concatenate([members[i] for i in pick]))
    low, high = np.percentile(values, [50.0 * (1.0 - level), 50.0 * (1.0 + level)])
    return float(statistic(np.arange(len(inverse)))), float(low), float(high)


def _r2(t: np.ndarray, p: np.ndarray) -> float:
    """R^2 of ``p`` about ``t``'s own mean (NaN where ``t`` is constant)."""
    tot = float(np.sum((t - t.mean()) ** 2))
    return 1.0 - float(np.sum((t - p) ** 2)) / tot if tot > 0 else float("nan")


def _parts(groups: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """``(group, its records)`` for each group, then ``("all", every record)``."""
    groups = np.asarray(groups)
    parts = [(str(g), np.flatnonzero(groups == g)) for g in sorted(set(groups.tolist()))]
    return [*parts, ("all", np.arange(len(groups)))]


def paired_r2_difference(
    y: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    groups: np.ndarray,
    clusters: np.ndarray,
    *,
    n_boot: int = 2000,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """``R^2(a) - R^2(b)`` per group (about the group's own mean) and over all records
    (``"all"``), with its 95 % interval over resamples of the ``clusters`` that score both
    predictions on the same records (paired: an interval that excludes 0 says one model
    predicts better on these people, whatever the spread of either's R^2)."""
    y, a, b = (np.asarray(v, dtype=float) for v in (y, a, b))
    clusters = np.asarray(clusters)
    out = {}
    for g, idx in _parts(groups):
        t, pa, pb = y[idx], a[idx], b[idx]
        value, low, high = cluster_bootstrap(
            lambda i, t=t, pa=pa, pb=pb: _r2(t[i], pa[i]) - _r2(t[i], pb[i]),
            clusters[idx],
            n_boot=n_boot,
            seed=seed,
        )
        out[g] = {"r2": value, "low": low, "high": high}
    return out


def r2_with_intervals(
    y: np.ndarray,
    predictions: dict[str, np.ndarray],
    groups: np.ndarray,
    clusters: np.ndarray,
    *,
    n_boot: int = 2000,
    seed: int = 0,
) -> dict[str, dict[str, dict[str, float]]]:
    """R^2 of each prediction per group and over all records, with bootstrap intervals.

    For each model (key of ``predictions``) and each group (for example a held-out
    participant), ``r2 = 1 - SS_res / SS_tot`` on the group's records, ``SS_tot`` about the
    group's own mean, and its 95 % interval over resamples of the group's ``clusters`` (its
    trials: :func:`cluster_bootstrap`); the key ``"all"`` is the same on every record
    (clusters resampled across groups). Also ``mse`` and ``n``. Why per group: the pooled
    R^2 credits a model for the differences between groups, which says nothing of how it
    predicts one new person.
    """
    y = np.asarray(y, dtype=float)
    clusters = np.asarray(clusters)
    out: dict[str, dict[str, dict[str, float]]] = {}
    parts = _parts(groups)
    for name, pred in predictions.items():
        pred = np.asarray(pred, dtype=float)
        out[name] = {}
        for g, idx in parts:
            t, p = y[idx], pred[idx]
            value, low, high = cluster_bootstrap(
                lambda i, t=t, p=p: _r2(t[i], p[i]), clusters[idx], n_boot=n_boot, seed=seed
            )
            out[name][g] = {
                "r2": value,
                "low": low,
                "high": high,
                "mse": float(np.mean((t - p) ** 2)),
                "n": len(idx),
            }
    return out
