"""A sweep's summary: the best cases and plots of a metric against the varied axes.

``best.md``: the ``count`` finished cases with the lowest objective (the campaign's
``objective``, a column of ``results.csv``: ``tracking_error_max_m``, ``final_error_m``,
``mae_max_m``, ``solver_failures``, ...), their varied values and the main metrics.
``axes.png``: the objective against each varied axis (every case a dot; a grid or
categorical axis' mean per value a line); ``heatmap.png``: with two grid axes, the
objective's mean over each pair of values.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from wholebody.files import save_figure, write_text
from wholebody.sweep.campaign import Campaign

__all__ = ["best_cases", "write_report"]

SHOWN = (
    "tracking_error_max_m",
    "final_error_m",
    "closed_chain_error_max_m",
    "solver_failures",
    "limit_violations",
)


def _value(row: dict[str, Any], key: str) -> float:
    value = row.get(key)
    return (
        float(value) if isinstance(value, int | float) and not isinstance(value, bool) else math.nan
    )


def _mean(values: np.ndarray) -> float:
    """The mean of the finite values (NaN if none)."""
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else math.nan


def best_cases(rows: Sequence[dict[str, Any]], objective: str, count: int = 5) -> list[dict]:
    """The ``count`` successful rows with the lowest finite ``objective``."""
    ok = [r for r in rows if r["status"] == "ok" and math.isfinite(_value(r, objective))]
    return sorted(ok, key=lambda r: _value(r, objective))[:count]


def write_report(campaign: Campaign, rows: Sequence[dict[str, Any]], out: Path) -> dict[str, Path]:
    """``best.md`` and the plots (module docstring); the files written."""
    best = _best_markdown(campaign, rows, [a.key for a in campaign.axes])
    files = {"best": write_text(out / "best.md", best)}
    if campaign.axes and rows:
        files["axes"] = save_figure(_axes_figure(rows, campaign), out / "axes.png")
    grid = [a for a in campaign.axes if a.kind == "grid"]
    if len(grid) == 2 and rows:
        files["heatmap"] = save_figure(
            _heatmap(rows, grid, campaign.objective), out / "heatmap.png"
        )
    return files


def _key(value: Any) -> str:
    """A value as a hashable, comparable label (lists and tables too)."""
    return json.dumps(value, sort_keys=True)


def _best_markdown(campaign: Campaign, rows: Sequence[dict], keys: list[str]) -> str:
    best = best_cases(rows, campaign.objective)
    failed = sum(r["status"] != "ok" for r in rows)
    shown = [m for m in SHOWN if m != campaign.objective]
    head = ["case", *keys, campaign.objective, *shown]
    if rows and failed == len(rows):
        missing = " Every case failed: the errors are in results.csv."
    elif not any(campaign.objective in r for r in rows if r["status"] == "ok"):
        missing = f" No case has the metric {campaign.objective!r}: see results.csv's columns."
    else:
        missing = ""
    lines = [
        f"# {campaign.name}: the best of {len(rows)} cases by {campaign.objective}",
        "",
        f"{failed} failed or stopped (results.csv has why).{missing}",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in best:
        cells = [str(r["index"]), *(str(r.get(k, "")) for k in keys)]
        cells += [f"{_value(r, m):.6g}" for m in (campaign.objective, *shown)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _axes_figure(rows: Sequence[dict], campaign: Campaign):
    """The objective against each axis: numbers on a numeric axis, one column per value on
    another (a backend, a goal); a grid axis' mean per value as a line."""
    axes_ = campaign.axes
    fig = Figure(figsize=(4.2 * len(axes_), 3.6), layout="constrained")
    panels = np.atleast_1d(fig.subplots(1, len(axes_)))
    y = np.array([_value(r, campaign.objective) for r in rows])
    for ax, axis in zip(panels, axes_, strict=True):
        numeric = all(math.isfinite(_value(r, axis.key)) for r in rows)
        if numeric:
            x = np.array([_value(r, axis.key) for r in rows])
            labels = None
        else:  # categories, in the campaign's order
            order = [_key(v) for v in (axis.values or axis.bounds)]
            x = np.array(
                [
                    order.index(_key(r.get(axis.key)))
                    if _key(r.get(axis.key)) in order
                    else math.nan
                    for r in rows
                ],
                dtype=float,
            )
            labels = [str(v) for v in (axis.values or axis.bounds)]
        ax.plot(x, y, "o", ms=3, alpha=0.5, color="#1f77b4")
        if axis.kind == "grid" or labels is not None:
            values = np.unique(x[np.isfinite(x)])
            ax.plot(
                values,
                [_mean(y[x == v]) for v in values],
                "-",
                color="#d62728",
                lw=1.5,
                label="mean",
            )
            ax.legend(fontsize=8, frameon=False)
        if labels is not None:
            ax.set_xticks(range(len(labels)), labels, rotation=20, fontsize=7)
        ax.set_xlabel(axis.key)
        ax.set_ylabel(campaign.objective)
        ax.grid(alpha=0.3)
    return fig


def _heatmap(rows: Sequence[dict], grid: list, objective: str):
    """The objective's mean over each pair of the two grid axes' values (campaign order)."""
    a, b = grid
    xs, ys = [_key(v) for v in a.values], [_key(v) for v in b.values]
    mean = np.full((len(ys), len(xs)), np.nan)
    for i, yv in enumerate(ys):
        for j, xv in enumerate(xs):
            cell = [
                _value(r, objective)
                for r in rows
                if _key(r.get(a.key)) == xv and _key(r.get(b.key)) == yv
            ]
            mean[i, j] = _mean(np.array(cell, dtype=float))
    fig = Figure(figsize=(1.2 * len(xs) + 3, 0.6 * len(ys) + 2.5), layout="constrained")
    ax = fig.subplots()
    image = ax.imshow(mean, origin="lower", aspect="auto", cmap="viridis")
    ax.set_xticks(range(len(xs)), [str(v) for v in a.values])
    ax.set_yticks(range(len(ys)), [str(v) for v in b.values])
    ax.set_xlabel(a.key)
    ax.set_ylabel(b.key)
    for i in range(len(ys)):
        for j in range(len(xs)):
            if np.isfinite(mean[i, j]):
                ax.text(j, i, f"{mean[i, j]:.3g}", ha="center", va="center", fontsize=8, color="w")
    fig.colorbar(image, ax=ax, label=f"{objective} (mean)")
    return fig
