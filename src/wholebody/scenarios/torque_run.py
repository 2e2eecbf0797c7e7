"""A scenario's phase at the torque level (``--backend dynamics``): the phase's stack under
:class:`~wholebody.dynamics.TorqueController`, at ``[torque] rate_hz``, with the scenario's
contacts and pushes, logged as a :class:`~wholebody.control.RunLog` like every other
backend's run (so metrics, plots and Table 2 read it the same), plus the torques and
contact wrenches in ``meta["torque"]``.

A floating base stands on its contacts: :func:`balanced` holds the centre of mass (x, y, z)
and the base's orientation above every other task, where they were when the phase began
(``[torque] com_kp``, 1/s), at every level of control (the runner applies it to a floating
base's stack whatever the backend).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody.control.log import ArmTrace, RunLog
from wholebody.dynamics import DynamicsSolver
from wholebody.dynamics.carry import CarriedObject, box_inertia
from wholebody.dynamics.controller import TorqueController, TorqueLog
from wholebody.errors import ConfigError
from wholebody.planning.trajectory import Trajectory
from wholebody.robot import Robot
from wholebody.scenarios.spec import ObjectSpec, ScenarioSpec
from wholebody.solvers.result import SolverStatus
from wholebody.solvers.stack import Level, Stack
from wholebody.tasks import ComTask, FrameTask

__all__ = ["Grasp", "balanced", "object_inertia", "torque_phase", "torque_solver"]


def torque_solver(spec: ScenarioSpec, robot: Robot) -> DynamicsSolver:
    """The solver of a scenario's torque-level run: ``[torque]``'s contacts, mode and gain
    (a clear error for a floating base with nothing to stand on)."""
    t = spec.torque
    if robot.base.floating and not t.contacts:
        raise ConfigError(
            f"{spec.path}: robot {robot.name!r} has a floating base: a torque-level run needs "
            f"its contacts ([torque.contacts.FRAME], e.g. the soles)"
        )
    contacts = [c.make() for c in t.contacts]
    return DynamicsSolver(
        robot,
        contacts,
        mode=t.mode,
        velocity_gain=t.velocity_gain,
        acceleration_limits=t.acceleration_limits,
    )


def balanced(robot: Robot, stack: Stack, q: np.ndarray, com_kp: float) -> Stack:
    """``stack`` with, above all, the centre of mass (x, y, z) held where it is at ``q`` and
    the base's orientation held as it is, for a floating base (else ``stack`` itself): what
    keeps a standing robot over its feet while the tasks below move it."""
    if not robot.base.floating or com_kp == 0.0:
        return stack
    com = ComTask(robot, "xyz", kp=com_kp, target=robot.com_position(q))
    base = FrameTask(robot, robot.base_frame, name="base orientation", position=False, kp=com_kp)
    base.set_target(robot.frame_pose(q, robot.base_frame))
    levels = [Level((com, base), name="balance"), *stack.levels]
    return Stack(robot, levels, stack.constraints)


def torque_phase(
    spec: ScenarioSpec,
    robot: Robot,
    stack: Stack,
    solver: DynamicsSolver,
    refs: Mapping[FrameTask, Trajectory],
    plant,
    q: np.ndarray,
    duration: float,
    *,
    t0: float = 0.0,
    u0: np.ndarray | None = None,
    monitors: Sequence = (),
    callback: Callable[[int, float, np.ndarray], None] | None = None,
    meta: Mapping[str, object] | None = None,
    grasp: Grasp | None = None,
) -> tuple[RunLog, TorqueLog]:
    """Run one phase from ``(q, u0)`` for ``duration`` s (``t0``: the phase's start in the
    run, which the pushes' times count from; ``grasp``: what the phase carries); the phase's
    :class:`RunLog` and its torques and wrenches
    (:class:`~wholebody.dynamics.controller.TorqueLog`)."""
    dt = spec.torque.dt
    _hold(spec, robot, solver, grasp, plant, q)
    if not solver.contacts_made:
        solver.make_contacts(q)
    controller = TorqueController(robot, stack, solver, dt=dt, references=refs, plant=plant)
    push = _pusher(spec, robot, plant, t0)

    def each(k: int, t: float, qk: np.ndarray, _result) -> None:
        if push is not None:
            push(t0 + t)
        if callback is not None:
            callback(k, t, qk)

    if push is not None:
        push(t0)
    tlog = controller.run(q, duration, u0=u0, callback=each)
    info = {
        "robot": robot.name,
        "dt": dt,
        "solver": solver.name,
        "levels": [[e.name for e in lv.entries] for lv in stack.levels],
        "actuated_joints": list(robot.actuated_joints),
        "groups": {g: grp.indices.tolist() for g, grp in robot.groups.items()},
        "position_limits": [lim.tolist() for lim in robot.position_limits],
        "orientation_rows": {
            t.name: np.flatnonzero(t.rows >= 3).tolist()
            for t in stack.tasks
            if isinstance(t, FrameTask)
        },
        "final_q": np.asarray(tlog.meta["final_q"]).tolist(),
        "final_u": np.asarray(tlog.meta.get("final_u", tlog.u[-1])).tolist(),
        **({"stopped": tlog.meta["stopped"]} if "stopped" in tlog.meta else {}),
        **(meta or {}),
    }
    return _run_log(robot, stack, refs, monitors, tlog, info), tlog


@dataclass
class Grasp:
    """What a phase carries: object -> its hands' frames (the primary first), the squeeze
    (N) to hold, and each object's pose in its first hand's frame as last held (kept from
    phase to phase: a kinematic run has no object to read it from)."""

    carried: dict[str, tuple[str, ...]]
    squeeze: float | None = None
    offsets: dict[str, np.ndarray] = field(default_factory=dict)


def _hold(
    spec: ScenarioSpec, robot: Robot, solver: DynamicsSolver, grasp: Grasp | None, plant, q
) -> None:
    """The solver's carried objects those of ``grasp`` (released otherwise), each held where
    it is: the simulation's pose, else where the hand took it (its scenario pose at the
    first grasp)."""
    carried = grasp.carried if grasp is not None else {}
    for obj in list(solver.objects):
        if obj.name not in carried:
            solver.release(obj.name)
    if grasp is None:
        return
    for name, hands in carried.items():
        obj = spec.objects[name]
        if obj.mass is None:
            raise ConfigError(
                f"{spec.path}: object {name!r} has no mass: a torque-level run carrying it "
                f"needs one (objects.mass, kg)"
            )
        hand = robot.frame_pose(q, hands[0])
        if plant is not None:
            pose = plant.object_poses()[name]
        else:
            pose = hand @ grasp.offsets[name] if name in grasp.offsets else obj.pose
        grasp.offsets[name] = np.linalg.solve(hand, pose)
        carried_object = CarriedObject(
            name,
            obj.mass,
            object_inertia(obj),
            hands,
            squeeze=grasp.squeeze,
            mu=spec.torque.grasp_mu,
        )
        solver.carry(carried_object, q, pose)


def object_inertia(obj: ObjectSpec) -> np.ndarray:
    """A scenario object's rotational inertia (kg m^2, about its centre, its axes) as a
    uniform solid of its mass."""
    m = float(obj.mass or 0.0)
    if obj.kind == "box":
        return box_inertia(m, obj.size)
    if obj.kind == "cylinder":  # axis z
        r, h = obj.radius, obj.height
        side = m * (3 * r * r + h * h) / 12.0
        return np.diag([side, side, 0.5 * m * r * r])
    if obj.kind == "sphere":
        return np.eye(3) * 0.4 * m * obj.radius**2
    raise ConfigError(f"object {obj.name!r}: no inertia for a {obj.kind!r}")


def _pusher(spec: ScenarioSpec, robot: Robot, plant, t0: float) -> Callable[[float], None] | None:
    """A function of the run's time setting each push's force on its body (MuJoCo's
    ``xfrc_applied``, world axes, at the body's centre of mass) while it lasts; None without
    pushes or without a plant (a kinematic run has nothing to push)."""
    pushes = spec.torque.pushes
    if not pushes or plant is None:
        return None
    bodies = []
    for p in pushes:
        body = plant.body_of(p.frame)
        bodies.append((body, np.asarray(p.force), p.start, p.start + p.duration))

    def push(t: float) -> None:
        applied = plant.data.xfrc_applied
        for body, _, _, _ in bodies:
            applied[body, :3] = 0.0
        for body, force, start, end in bodies:
            if start <= t < end:
                applied[body, :3] += force

    return push


def _run_log(
    robot: Robot,
    stack: Stack,
    refs: Mapping[FrameTask, Trajectory],
    monitors: Sequence,
    tlog: TorqueLog,
    meta: dict,
) -> RunLog:
    """The torque run as a :class:`RunLog`: each step's kinematics recomputed at its logged
    configuration, the referenced tasks' targets set as they were at that step."""
    n, tasks = len(tlog.t), stack.tasks
    tracked = [t for t in tasks if isinstance(t, FrameTask)]
    errors = {t.name: np.zeros((n, t.dim)) for t in tasks}
    pos = {t.name: np.zeros((n, 3)) for t in tracked}
    ref = {t.name: np.zeros((n, 3)) for t in tracked}
    arms = {m.arm.name: np.zeros((n, 6)) for m in monitors}
    jp = np.zeros((n, robot.nu))
    for k in range(n):
        for task, r in refs.items():
            task.set_target(r.sample(min(tlog.t[k], r.duration)).pose)
        state = robot.update(tlog.q[k])
        jp[k] = state.joint_positions()
        for task in tasks:
            errors[task.name][k] = task.error(state)
        for task in tracked:
            pos[task.name][k] = state.position(task.frame)
            ref[task.name][k] = task.target[:3, 3] if task.target is not None else np.nan
        for m in monitors:
            arms[m.arm.name][k] = m.parts(state)
    limited = (tlog.status == SolverStatus.BOUNDS_ACTIVE) | (tlog.status == SolverStatus.SCALED)
    return RunLog(
        t=tlog.t,
        q=tlog.q,
        u=tlog.u,
        joint_positions=jp,
        step_time=tlog.step_time,
        solve_time=tlog.step_time,
        status=tlog.status,
        limit_hit=limited,
        level_residuals=np.full((n, len(stack.levels)), np.nan),
        task_errors=errors,
        frame_positions=pos,
        reference_positions=ref,
        arms={a: ArmTrace(*v.T.copy()) for a, v in arms.items()},
        meta=meta,
        failed=tlog.status == SolverStatus.FAILED,
    )
