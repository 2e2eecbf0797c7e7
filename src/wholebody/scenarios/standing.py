"""What a torque-level run adds to a scenario's metrics: the bounds held, and for a robot on
its contacts whether it stood.

The standing metrics need contacts (a robot without contacts gets ``violation_max`` only).
Read from the controller's records (:class:`~wholebody.dynamics.controller.TorqueLog`: the
torques and the wrenches it commanded) and from the true configurations (a physics run's
simulated ones, else the integrated ones):

``violation_max``
    The largest excess of a commanded torque, wrench or the equations of motion over its
    bound (N m, N): 0 when every bound held.
``cop_margin_min_m``
    The least distance from a patch contact's centre of pressure (of the commanded wrench)
    to its sole's edge (m); negative outside.
``foot_slip_max_m``
    Per contact frame, its largest horizontal displacement (m, world) from where the run
    began, and ``foot_slip_max_m_all`` the largest of them.
``com_excursion_max_m``
    The largest horizontal distance (m) of the centre of mass from where it began.
``fell``
    The base dropped more than 0.2 m below where it began, a contact slid more than 5 cm, or
    the simulation stopped.
``com_after_push_m``
    With pushes: the centre of mass's horizontal distance at the run's end from where it was
    when the first push began (m): it recovered when that is small.
``squeeze_error_max_n``
    Per carried object with a squeeze setpoint (``[[phases]] squeeze_n``), the largest
    distance (N) of its squeeze from the setpoint over the phases that set one: the
    simulation's (measured at the welds) in a physics run, else the commanded wrenches'.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wholebody.dynamics import DynamicsSolver, PatchContact
from wholebody.dynamics.controller import TorqueLog
from wholebody.robot import Robot
from wholebody.scenarios.torque_spec import PushSpec

__all__ = ["squeeze_errors", "torque_arrays", "torque_metrics"]

FALL_DROP = 0.2
"""m: a base lower than this below its start has fallen."""
FALL_SLIP = 0.05
"""m: a contact that slid this far has been lost."""


def torque_arrays(logs: Sequence[TorqueLog]) -> dict[str, np.ndarray]:
    """The torque-level records of consecutive phases (``torque.npz``): ``tau`` (N, nu; N m,
    N, in ``u``'s order), ``wrench/FRAME`` (N, 6 or 3), ``violation`` (N; N m or N),
    ``squeeze/OBJECT`` (N; N, NaN while not held by the controller)."""
    out = {
        "tau": np.concatenate([g.tau for g in logs]),
        "violation": np.concatenate([g.violation for g in logs]),
    }
    for frame in logs[0].wrenches:
        out[f"wrench/{frame}"] = np.concatenate([g.wrenches[frame] for g in logs])
    for obj in sorted({o for g in logs for o in g.squeeze}):
        out[f"squeeze/{obj}"] = np.concatenate(
            [g.squeeze.get(obj, np.full(len(g.t), np.nan)) for g in logs]
        )
    return out


def squeeze_errors(
    setpoints: Sequence[tuple[np.ndarray, float]], squeeze: dict[str, np.ndarray]
) -> dict[str, float]:
    """Per object, the largest ``|s - setpoint|`` (N) over the steps of ``setpoints`` (pairs
    of a step mask and the setpoint there) where the object is held (``s`` finite)."""
    out = {}
    for obj, s in squeeze.items():
        errors = [np.abs(s[mask] - value) for mask, value in setpoints]
        errors = [e[np.isfinite(e)] for e in errors]
        if any(e.size for e in errors):
            out[obj] = float(max(e.max(initial=0.0) for e in errors))
    return out


def torque_metrics(
    robot: Robot,
    solver: DynamicsSolver,
    arrays: dict[str, np.ndarray],
    q: np.ndarray,
    t: np.ndarray,
    pushes: Sequence[PushSpec] = (),
    stopped: bool = False,
) -> dict:
    """The module docstring's metrics; ``q`` (N, nq) the true configurations at times ``t``
    (s)."""
    m: dict = {"violation_max": float(arrays["violation"].max(initial=0.0))}
    patches = [c for c in solver.contacts if isinstance(c, PatchContact)]
    if patches:
        m["cop_margin_min_m"] = float(
            min(min(c.cop_margin(w) for w in arrays[f"wrench/{c.frame}"]) for c in patches)
        )
    if not solver.contacts:  # nothing to stand on: only the bounds
        return m
    base = robot.base_frame.name
    positions, com = _trajectories(robot, q, [*(c.frame for c in solver.contacts), base])
    slip = {c.frame: _largest_shift(positions[c.frame]) for c in solver.contacts}
    m["foot_slip_max_m"] = slip
    m["foot_slip_max_m_all"] = max(slip.values(), default=0.0)
    m["com_excursion_max_m"] = _largest_shift(com)
    drop = 0.0
    if robot.base.floating:
        height = positions[base][:, 2]
        drop = float(height[0] - height.min())
    m["fell"] = bool(stopped or drop > FALL_DROP or m["foot_slip_max_m_all"] > FALL_SLIP)
    if pushes:
        k = min(int(np.searchsorted(t, min(p.start for p in pushes))), len(t) - 1)
        m["com_after_push_m"] = float(np.linalg.norm(com[-1, :2] - com[k, :2]))
    return m


def _trajectories(
    robot: Robot, q: np.ndarray, frames: Sequence[str]
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per configuration of ``q`` (N, nq), each frame's position and the centre of mass
    (N x 3 each, m, world), from one kinematics update a configuration."""
    parts = {f: robot.frame(f) for f in frames}
    positions = {f: np.empty((len(q), 3)) for f in parts}
    com = np.empty((len(q), 3))
    for k, qk in enumerate(q):
        state = robot.update(qk)
        for f, part in parts.items():
            positions[f][k] = state.position(part)
        com[k] = state.com_position()
    return positions, com


def _largest_shift(p: np.ndarray) -> float:
    """The largest horizontal distance (m) of the points ``p`` (N x 3) from the first."""
    return float(np.linalg.norm(p[:, :2] - p[0, :2], axis=1).max())
