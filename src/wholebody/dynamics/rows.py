"""One level's rows at the torque level (:class:`Rows`), and the operations the solver
builds its levels with: a named equality level, a level padded with the wrenches' columns,
a level with extra rows below its own."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.solvers.stack import OBJECTIVES, LevelProblem

__all__ = ["Rows", "equality_level", "padded", "with_rows"]


@dataclass(slots=True)
class Rows:
    """One level's rows, in the order of :class:`~wholebody.solvers.stack.LevelProblem`'s
    fields, without its reporting machinery: built every step, turned into a
    ``LevelProblem`` only when the cascade's arena is laid out (:meth:`level`)."""

    name: str
    A: np.ndarray
    b: np.ndarray
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    task_rows: dict[str, slice]
    inequality_rows: dict[str, slice]
    identity_scale: float = 0.0
    unweight: np.ndarray | None = None
    reference_scale: float = 1.0

    def level(self) -> LevelProblem:
        return LevelProblem(
            self.name,
            self.A,
            self.b,
            self.C,
            self.lower,
            self.upper,
            self.task_rows,
            self.inequality_rows,
            self.identity_scale,
            self.unweight,
            self.reference_scale,
        )

    def key(self) -> tuple:
        """What the arena's layout depends on."""
        return (
            self.name,
            self.A.shape,
            self.C.shape,
            tuple((k, s.start, s.stop) for k, s in self.task_rows.items()),
            tuple((k, s.start, s.stop) for k, s in self.inequality_rows.items()),
        )


def equality_level(name: str, A: np.ndarray, b: np.ndarray, n: int) -> Rows:
    """An equality level of one task of the same name."""
    empty = np.zeros(0)
    rows = {name: slice(0, A.shape[0])}
    return Rows(name, A, b, np.zeros((0, n)), empty, empty.copy(), rows, {})


def with_rows(lp: Rows, extra: Rows, weight: float) -> Rows:
    """``lp`` with ``extra``'s equality rows times ``weight`` below its own, named as
    ``extra``'s with `` (regularisation)``."""
    if weight == 0.0 or not lp.A.shape[0] or OBJECTIVES in lp.task_rows:
        return lp  # (an objectives' level's rows come last: the last level does it)
    k, m = lp.A.shape[0], extra.A.shape[0]
    rows = dict(lp.task_rows)
    rows[f"{extra.name} (regularisation)"] = slice(k, k + m)
    unweight = np.ones(k) if lp.unweight is None else lp.unweight
    return Rows(
        lp.name,
        np.vstack([lp.A, weight * extra.A]),
        np.concatenate([lp.b, weight * extra.b]),
        lp.C,
        lp.lower,
        lp.upper,
        rows,
        lp.inequality_rows,
        lp.identity_scale,
        np.concatenate([unweight, np.full(m, 1.0 / weight)]),
        lp.reference_scale,
    )


def padded(lp: Rows, n: int) -> Rows:
    """``lp`` with zero columns for the wrenches (``n`` columns in all), its equality rows
    divided by ``max(1, ||b||)``: the same optimum, and a residual of order 1 at most, so
    that the cascade's tolerances (relative to the residual) stay tight on the constraints
    the level inherits."""
    pad = n - lp.A.shape[1]
    s = 1.0 / max(1.0, float(np.linalg.norm(lp.b)))
    return Rows(
        lp.name,
        np.hstack([lp.A * s, np.zeros((lp.A.shape[0], pad))]),
        lp.b * s,
        np.hstack([lp.C, np.zeros((lp.C.shape[0], pad))]),
        lp.lower,
        lp.upper,
        lp.task_rows,
        lp.inequality_rows,
        0.0,
        np.full(lp.A.shape[0], 1.0 / s) if lp.unweight is None else lp.unweight / s,
        lp.reference_scale * s,
    )
