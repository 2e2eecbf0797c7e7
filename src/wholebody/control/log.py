"""The run log: everything a control run produced, saved to and loaded from ``.npz``.

Arrays have one row per control step. Keys in the file (no pickle; metadata as JSON)::

    t, q, u, joint_positions, step_time, solve_time, status, limit_hit, level_residuals
    failed                          (N,) bool: a task that could be met was not (the solve
                                    failed, or left a level worse than the constraints force:
                                    :mod:`wholebody.solvers.unmet`; any backend)
    unmet/<task>                    (N,) int8 why the task was unmet (UnmetCause; 0: met)
    task_error/<task>               (N, dim)  task errors (m, rad)
    frame_position/<task>           (N, 3)    tracked frame position (m, world)
    reference_position/<task>       (N, 3)    its reference (m, world)
    arm/<arm>/{energy,gravity,spring,arm_angle,stiffness,rho}  (N,)  J, J, J, rad, N m/rad, m
    objective/<name>                (N,)      a monitored objective's value (unweighted)
    meta                            JSON: robot, dt, solver, levels, actuated joints, groups,
                                    position limits, phases
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wholebody.errors import DataError
from wholebody.files import read_npz, write_npz

__all__ = ["ArmTrace", "RunLog", "concatenate"]

ARM_FIELDS = ("energy", "gravity", "spring", "arm_angle", "stiffness", "rho")


def json_default(value: object) -> object:
    """``json.dumps``'s ``default`` for numpy scalars and arrays (the metadata of logs and
    scenario outputs)."""
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@dataclass
class ArmTrace:
    """Per-step energy terms of one arm (J, J, J, rad, N m/rad) and ``rho`` (m), how well
    the arm angle is defined (0 for a straight arm or a vertical shoulder-wrist line)."""

    energy: np.ndarray
    gravity: np.ndarray
    spring: np.ndarray
    arm_angle: np.ndarray
    stiffness: np.ndarray
    rho: np.ndarray


@dataclass
class RunLog:
    """A control run, one row per step (see the module docstring for units)."""

    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    joint_positions: np.ndarray
    step_time: np.ndarray
    solve_time: np.ndarray
    status: np.ndarray
    limit_hit: np.ndarray
    level_residuals: np.ndarray
    task_errors: dict[str, np.ndarray] = field(default_factory=dict)
    frame_positions: dict[str, np.ndarray] = field(default_factory=dict)
    reference_positions: dict[str, np.ndarray] = field(default_factory=dict)
    arms: dict[str, ArmTrace] = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    failed: np.ndarray | None = None
    """Per step: a task that could be met was not (the solve failed, or left a level worse
    than the constraints force; :func:`wholebody.solvers.unmet.classify`), by the same rule
    for every backend; None in logs written before it was recorded (logs written before
    the causes were recorded have the older rule: the first level unmet)."""
    objectives: dict[str, np.ndarray] = field(default_factory=dict)
    """Per monitored objective other than an arm energy, its value each step."""
    unmet: dict[str, np.ndarray] | None = None
    """Per equality task, each step's :class:`~wholebody.solvers.unmet.UnmetCause` (int8, 0:
    met); None in logs written before it was recorded."""

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def dt(self) -> float:
        return float(self.meta.get("dt", 0.0))

    def group_indices(self, group: str) -> np.ndarray:
        """Indices into ``u`` of a joint group recorded in the metadata."""
        try:
            return np.asarray(self.meta["groups"][group], dtype=int)
        except KeyError:
            raise DataError(
                f"run log has no joint group {group!r}; it has "
                f"{sorted(self.meta.get('groups', {}))}"
            ) from None

    def phase_mask(self, phase: str) -> np.ndarray:
        """Boolean mask of the steps inside a named phase (``meta['phases']``)."""
        phases = self.meta.get("phases", {})
        if phase not in phases:
            raise DataError(f"run log has no phase {phase!r}; it has {sorted(phases)}")
        t0, t1 = phases[phase]
        return (self.t >= t0 - 1e-9) & (self.t < t1 - 1e-9)

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        """Write the log as a compressed ``.npz`` (no pickle)."""
        path = Path(path)
        arrays: dict[str, np.ndarray] = {
            "t": self.t,
            "q": self.q,
            "u": self.u,
            "joint_positions": self.joint_positions,
            "step_time": self.step_time,
            "solve_time": self.solve_time,
            "status": self.status,
            "limit_hit": self.limit_hit,
            "level_residuals": self.level_residuals,
        }
        if self.failed is not None:
            arrays["failed"] = self.failed
        for prefix, table in (
            ("task_error", self.task_errors),
            ("frame_position", self.frame_positions),
            ("reference_position", self.reference_positions),
            ("objective", self.objectives),
            ("unmet", self.unmet or {}),
        ):
            for name, value in table.items():
                arrays[f"{prefix}/{name}"] = value
        for arm, trace in self.arms.items():
            for f in ARM_FIELDS:
                arrays[f"arm/{arm}/{f}"] = getattr(trace, f)
        arrays["meta"] = np.array(json.dumps(self.meta, default=json_default))
        return write_npz(path, arrays)

    @classmethod
    def load(cls, path: str | Path) -> RunLog:
        """Read a log written by :meth:`save`."""
        path = Path(path)
        data = read_npz(path, "run log (.npz)")
        required = (
            "t",
            "q",
            "u",
            "joint_positions",
            "step_time",
            "solve_time",
            "status",
            "limit_hit",
            "level_residuals",
            "meta",
        )
        missing = [k for k in required if k not in data]
        if missing:
            raise DataError(f"{path}: run log lacks {missing}")
        tables: dict[str, dict[str, np.ndarray]] = {
            "task_error": {},
            "frame_position": {},
            "reference_position": {},
            "objective": {},
            "unmet": {},
        }
        arms: dict[str, dict[str, np.ndarray]] = {}
        for key, value in data.items():
            head, _, rest = key.partition("/")
            if head in tables:
                tables[head][rest] = value
            elif head == "arm":
                arm, _, f = rest.partition("/")
                arms.setdefault(arm, {})[f] = value
        for arm, fields in arms.items():
            lacking = [f for f in ARM_FIELDS if f not in fields]
            if lacking:
                raise DataError(f"{path}: arm trace {arm!r} lacks {', '.join(lacking)}")
        _check_lengths(path, data)
        return cls(
            **{k: data[k] for k in required if k != "meta"},
            task_errors=tables["task_error"],
            frame_positions=tables["frame_position"],
            reference_positions=tables["reference_position"],
            arms={a: ArmTrace(**{f: v[f] for f in ARM_FIELDS}) for a, v in arms.items()},
            meta=_meta(path, data["meta"]),
            failed=data.get("failed"),
            objectives=tables["objective"],
            unmet=tables["unmet"] if "unmet" in _heads(data) else None,
        )


def _heads(data: dict[str, np.ndarray]) -> set[str]:
    """The first parts of a log file's keys (``unmet`` for ``unmet/<task>``)."""
    return {key.partition("/")[0] for key in data}


def _meta(path: Path, value: np.ndarray) -> dict:
    """A log's metadata: a JSON object in a 0-d string array."""
    if value.ndim != 0 or value.dtype.kind != "U":
        raise DataError(
            f"{path}: key 'meta': expected a 0-d string, got {value.dtype} {value.shape}"
        )
    try:
        meta = json.loads(str(value))
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: key 'meta' is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise DataError(f"{path}: key 'meta' must be a JSON object, got {type(meta).__name__}")
    return meta


def _check_lengths(path: Path, data: dict[str, np.ndarray]) -> None:
    """Every per-step array has one row per entry of ``t``."""
    n = data["t"].shape[0] if data["t"].ndim == 1 else -1
    if n < 0:
        raise DataError(f"{path}: key 't': expected shape (T,), got {data['t'].shape}")
    for key, value in data.items():
        if key != "meta" and (value.ndim == 0 or value.shape[0] != n):
            raise DataError(
                f"{path}: key {key!r} has {value.shape[0] if value.ndim else 0} rows, 't' has {n}"
            )


def concatenate(logs: list[RunLog], meta: dict | None = None) -> RunLog:
    """One log from consecutive runs (e.g. the phases of a scenario), times shifted to run on.

    Tasks, tracked frames or arms present in only some of the runs are padded with NaN where
    absent; level residuals are padded to the largest number of levels.
    """
    if not logs:
        raise DataError("nothing to concatenate")
    periods = {log.dt for log in logs}
    if len(periods) > 1:  # the metrics read one dt from the metadata
        raise DataError(
            f"cannot concatenate runs with different control periods: dt = {sorted(periods)} s"
        )
    t, offset = [], 0.0
    for log in logs:
        t.append(log.t + offset)
        offset += len(log) * log.dt
    width = max(log.level_residuals.shape[1] for log in logs)

    def pad_levels(a: np.ndarray) -> np.ndarray:
        out = np.full((a.shape[0], width), np.nan)
        out[:, : a.shape[1]] = a
        return out

    def merge(tables: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        keys: dict[str, int] = {}
        for tab in tables:
            for k, v in tab.items():
                keys.setdefault(k, v.shape[1] if v.ndim > 1 else 0)
        out = {}
        for k, cols in keys.items():
            parts = []
            for log, tab in zip(logs, tables, strict=True):
                shape = (len(log), cols) if cols else (len(log),)
                parts.append(tab.get(k, np.full(shape, np.nan)))
            out[k] = np.concatenate(parts)
        return out

    arms = {}
    for arm in {a for log in logs for a in log.arms}:
        arms[arm] = ArmTrace(
            **{
                f: np.concatenate(
                    [
                        getattr(log.arms[arm], f) if arm in log.arms else np.full(len(log), np.nan)
                        for log in logs
                    ]
                )
                for f in ARM_FIELDS
            }
        )
    base = dict(logs[-1].meta)
    base.update(meta or {})
    return RunLog(
        t=np.concatenate(t),
        q=np.concatenate([log.q for log in logs]),
        u=np.concatenate([log.u for log in logs]),
        joint_positions=np.concatenate([log.joint_positions for log in logs]),
        step_time=np.concatenate([log.step_time for log in logs]),
        solve_time=np.concatenate([log.solve_time for log in logs]),
        status=np.concatenate([log.status for log in logs]),
        limit_hit=np.concatenate([log.limit_hit for log in logs]),
        level_residuals=np.concatenate([pad_levels(log.level_residuals) for log in logs]),
        task_errors=merge([log.task_errors for log in logs]),
        frame_positions=merge([log.frame_positions for log in logs]),
        reference_positions=merge([log.reference_positions for log in logs]),
        arms=arms,
        meta=base,
        failed=(
            None
            if any(log.failed is None for log in logs)
            else np.concatenate([log.failed for log in logs])
        ),
        objectives=merge([log.objectives for log in logs]),
        unmet=_merge_causes(logs),
    )


def _merge_causes(logs: list[RunLog]) -> dict[str, np.ndarray] | None:
    """The runs' per-task unmet causes end to end, 0 (met) where a run lacks the task; None
    if a run did not record them."""
    if any(log.unmet is None for log in logs):
        return None
    names = list(dict.fromkeys(name for log in logs for name in log.unmet))  # type: ignore[union-attr]
    return {
        name: np.concatenate(
            [
                log.unmet.get(name, np.zeros(len(log), dtype=np.int8))  # type: ignore[union-attr]
                for log in logs
            ]
        )
        for name in names
    }
