"""Metrics of a run log: the paper's Table 2 quantities and the safety counts.

* tracking of each frame task against its reference: MSE (m^2) and MAE (m) per axis,
* control step time: its median and 90th percentile (us), and the rate the median step
  sustains, ``1 / median(step_time)`` (Hz; the paper's "decision frequency"). One statistic,
  the median, everywhere (the command line, ``metrics.json``, the comparison tables): a
  mean would be pulled up by the first steps (loading the kernels, warming the caches), so
  that a rate ``1 / mean`` beside a median step time contradicted it,
* joint travel per group: ``sum_k sum_j |u_kj| dt`` (rad; for wheels, wheel rotation),
* arm energies: initial, final, mean (J); arm angle range (rad) over the steps where it is
  defined (``rho >= ARM_ANGLE_MIN_RHO``: not a straight arm, not a vertical shoulder-wrist
  line),
* limit violations (steps with a joint outside its limits by more than 1e-9 rad) and solver
  failures: steps where a task that could be met was not (the solve failed, or left a level
  worse than the constraints force: :attr:`RunLog.failed`, the same rule for every backend;
  in logs without it, steps with status INFEASIBLE or FAILED),
* where each tracked hand ends: its distance from its last reference (its goal) at the last
  step, position (m) and rotation (rad), and whether that is within ``GOAL_TOLERANCE_M`` and
  ``GOAL_TOLERANCE_RAD`` (:func:`final_errors`),
* the steps with a task unmet, by cause (:func:`unmet_steps`): a task held back by a rate
  limit, at a joint limit, out of reach or yielding to a higher level is unmet but not a
  failure.
* u reversals: steps where some actuated velocity changed sign against the step before, both
  above ``REVERSAL_THRESHOLD`` (rad/s, m/s) in magnitude (:func:`u_reversals`). A run that
  settles has a few (a joint turning back as the motion changes); a limit cycle, the command
  alternating between two solutions, has one at nearly every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wholebody.control.log import RunLog
from wholebody.errors import DataError
from wholebody.solvers.result import SolverStatus
from wholebody.solvers.unmet import UnmetCause, worst

__all__ = [
    "GOAL_TOLERANCE_M",
    "GOAL_TOLERANCE_RAD",
    "Tracking",
    "closed_chain_error",
    "final_errors",
    "limit_overshoot",
    "limit_violations",
    "step_timing",
    "summary",
    "tracking",
    "u_reversals",
    "unmet_steps",
]

AXES = ("x", "y", "z")
ARM_ANGLE_MIN_RHO = 0.005  # m
GOAL_TOLERANCE_M = 1e-3  # a hand ending farther from its goal has not reached it (m)
GOAL_TOLERANCE_RAD = 0.01  # ... or turned farther from it (rad)
REVERSAL_THRESHOLD = 1e-3  # rad/s, m/s: a smaller velocity's sign is not counted


@dataclass(frozen=True)
class Tracking:
    """Position tracking of one frame task (per axis x, y, z)."""

    mse_m2: dict[str, float]
    mae_m: dict[str, float]
    max_m: float


def tracking(log: RunLog, task: str, mask: np.ndarray | None = None) -> Tracking:
    """Position tracking of a frame task against its reference over the masked steps."""
    if task not in log.frame_positions:
        raise DataError(
            f"run log has no tracked frame task {task!r}; it has {sorted(log.frame_positions)}"
        )
    err = log.frame_positions[task] - log.reference_positions[task]
    if mask is not None:
        err = err[mask]
    err = err[~np.isnan(err).any(axis=1)]  # steps where the task was not in the stack
    if err.size == 0:
        raise DataError(f"no steps selected for {task!r}")
    mse = np.mean(err**2, axis=0)
    mae = np.mean(np.abs(err), axis=0)
    return Tracking(
        dict(zip(AXES, map(float, mse), strict=True)),
        dict(zip(AXES, map(float, mae), strict=True)),
        float(np.max(np.linalg.norm(err, axis=1))),
    )


def limit_violations(log: RunLog, tolerance: float = 1e-9) -> int:
    """Number of steps with any joint outside its position limits by more than ``tolerance``."""
    lo, hi = (np.asarray(v, dtype=float) for v in log.meta["position_limits"])
    jp = log.joint_positions
    bad = (jp < lo - tolerance) | (jp > hi + tolerance)
    return int(np.count_nonzero(bad.any(axis=1)))


def limit_overshoot(log: RunLog) -> float:
    """The largest distance (rad or m) of any joint beyond its position limits (0 within)."""
    lo, hi = (np.asarray(v, dtype=float) for v in log.meta["position_limits"])
    jp = log.joint_positions
    if not len(jp):
        return 0.0
    return float(max(0.0, np.max(lo - jp), np.max(jp - hi)))


def closed_chain_error(log: RunLog, task: str, mask: np.ndarray | None = None) -> float:
    """Largest position error (m) of a relative (closed-chain) task over the masked steps."""
    if task not in log.task_errors:
        raise DataError(f"run log has no task {task!r}")
    e = log.task_errors[task][:, :3]
    if mask is not None:
        e = e[mask]
    e = e[~np.isnan(e).any(axis=1)]
    return float(np.max(np.linalg.norm(e, axis=1))) if e.size else 0.0


def u_reversals(u: np.ndarray, threshold: float = REVERSAL_THRESHOLD) -> int:
    """Number of steps k where some actuated velocity reversed: ``u_kj u_(k-1)j < 0`` with
    ``|u_kj|`` and ``|u_(k-1)j|`` both above ``threshold`` (rad/s, m/s). ``u``: (steps, nu)."""
    u = np.asarray(u, dtype=float)
    if u.ndim != 2:
        raise DataError(f"u must be (steps, nu), got shape {u.shape}")
    big = np.abs(u) > threshold
    flips = (u[1:] * u[:-1] < 0) & big[1:] & big[:-1]
    return int(np.count_nonzero(flips.any(axis=1)))


def step_timing(step_time: np.ndarray) -> dict[str, float]:
    """The control step's timing from per-step times (s): ``median_us`` and ``p90_us`` (us)
    and ``median_rate_hz = 1 / median`` (Hz), the rate the median step sustains. The median,
    not the mean, because the first steps of a process (kernels loading) are outliers."""
    median = float(np.median(step_time))
    return {
        "median_us": median * 1e6,
        "p90_us": float(np.percentile(step_time, 90) * 1e6),
        "median_rate_hz": 1.0 / median if median > 0 else float("inf"),
    }


def final_errors(log: RunLog) -> dict[str, dict]:
    """Per tracked frame task in the stack at the last step: ``position_m``, its distance
    from its reference there (m, world), ``rotation_rad``, the angle of its orientation
    error (rad; None for a task without orientation rows, or a log that does not say which
    rows those are: ``meta["orientation_rows"]``), and ``reached``: both within
    ``GOAL_TOLERANCE_M`` and ``GOAL_TOLERANCE_RAD``."""
    out: dict[str, dict] = {}
    if not len(log):
        return out
    rows = log.meta.get("orientation_rows", {})
    for task, position in log.frame_positions.items():
        off = position[-1] - log.reference_positions[task][-1]
        if not np.all(np.isfinite(off)):
            continue  # not in the stack at the end (no goal)
        rot = None
        if rows.get(task):
            rot = float(np.linalg.norm(log.task_errors[task][-1, rows[task]]))
        dist = float(np.linalg.norm(off))
        out[task] = {
            "position_m": dist,
            "rotation_rad": rot,
            "reached": dist <= GOAL_TOLERANCE_M and (rot is None or rot <= GOAL_TOLERANCE_RAD),
        }
    return out


def unmet_steps(log: RunLog) -> tuple[dict[str, int], dict[str, dict[str, int]]]:
    """Steps with a task unmet, by cause (:class:`~wholebody.solvers.unmet.UnmetCause`,
    lower-case names): each step once, under the most severe cause of its tasks; and per
    task, its steps by cause. Causes with no step are left out; empty for a log that did
    not record causes."""
    if not log.unmet:
        return {}, {}
    causes = np.stack(list(log.unmet.values()))
    name = {c.value: c.name.lower() for c in UnmetCause}
    steps = np.bincount(worst(causes, axis=0), minlength=len(name))
    per_task = {task: np.bincount(c, minlength=len(name)) for task, c in log.unmet.items()}
    return (
        {name[c]: int(n) for c, n in enumerate(steps) if c and n},
        {
            t: {name[c]: int(n) for c, n in enumerate(v) if c and n}
            for t, v in per_task.items()
            if v[1:].any()
        },
    )


def summary(log: RunLog) -> dict:
    """The metrics of a run as a JSON-ready dictionary (a :class:`DataError` for a log
    without steps)."""
    if not len(log):
        raise DataError("run log has no steps: no metrics")
    dt = log.dt
    timing = step_timing(log.step_time)
    out: dict = {
        "steps": len(log),
        "duration_s": float(len(log) * dt),
        "step_time_us": {"median": timing["median_us"], "p90": timing["p90_us"]},
        # 1 / the median step time above (Hz): the same statistic, as a rate
        "median_step_rate_hz": timing["median_rate_hz"],
        "mse_m2": {},
        "mae_m": {},
        "max_tracking_error_m": {},
        "joint_travel_rad": {
            g: float(np.sum(np.abs(log.u[:, log.group_indices(g)])) * dt)
            for g in log.meta.get("groups", {})
        },
        "limit_violations": limit_violations(log),
        "limit_violation_max": limit_overshoot(log),
        "solver_failures": int(
            np.count_nonzero(
                log.status >= SolverStatus.INFEASIBLE if log.failed is None else log.failed
            )
        ),
        "limit_hit_steps": int(np.count_nonzero(log.limit_hit)),
        # steps with a task unmet by cause, and per task ("failed" is solver_failures' share)
        **dict(zip(("unmet_steps", "unmet_tasks"), unmet_steps(log), strict=True)),
        "final_error": final_errors(log),
        "u_reversals": u_reversals(log.u),
        "arm_energy_j": {},
        "arm_angle_rad": {},
    }
    for task in log.frame_positions:
        tr = tracking(log, task)
        out["mse_m2"][task] = tr.mse_m2
        out["mae_m"][task] = tr.mae_m
        out["max_tracking_error_m"][task] = tr.max_m
    for arm, trace in log.arms.items():
        # rows where the arm was monitored (a concatenated log pads the others with NaN)
        rows = np.flatnonzero(np.isfinite(trace.energy))
        if not rows.size:
            continue
        energy = trace.energy[rows]
        out["arm_energy_j"][arm] = {
            "initial": float(energy[0]),
            "final": float(energy[-1]),
            "mean": float(np.mean(energy)),
            "gravity_final": float(trace.gravity[rows[-1]]),
        }
        defined = trace.arm_angle[rows][trace.rho[rows] >= ARM_ANGLE_MIN_RHO]
        out["arm_angle_rad"][arm] = {
            "min": float(np.min(defined)) if defined.size else float("nan"),
            "max": float(np.max(defined)) if defined.size else float("nan"),
            "defined_fraction": float(defined.size / rows.size),
        }
    return out
