"""Running a scenario: phases of hand references on the paper's stack, one log.

For every phase, in order:

1. each hand gets a reference that starts where its previous reference ended (the first
   phase starts at the hand's actual pose), so references never jump:
   ``free`` (no task: the hand is left to the objectives), ``hold`` (stay), ``min_jerk``
   (quintic to a goal), ``dmp`` (the scenario's DMP, learned
   once from its demonstration, generalised to the goal, with volumetric obstacle
   potentials for ``avoid``), ``follow`` (the primary hand's reference through the grasp
   transform fixed at the phase start: the secondary of the paper's coordinated mode);
   a goal orientation is the start orientation turned by ``rotate`` (world rotation vector);
2. the stack is the paper's (:func:`wholebody.presets.paper_stack`) with the hands on top
   and, for ``closed_chain`` phases, the relative pose of the secondary hand in the primary
   in a level above them (the grasp is met exactly, the hands' redundant rows in the least
   squares below); backend ``pinv`` drops the objectives;
3. a :class:`~wholebody.control.Controller` runs the phase from the current configuration,
   for a whole number of control steps: the phase's duration is rounded to the nearest
   multiple of ``dt`` (at least one step), and its references use that duration.

The logs are concatenated. A carried object follows its hand rigidly during each phase in
which it is carried (its pose relative to the hand fixed at that phase's start) and stays
where it was left otherwise.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from wholebody.arm.stiffness import StiffnessModel
from wholebody.collision import CollisionModel, Obstacle, PairDistance
from wholebody.control import Controller, JointSensor, RunLog, summary
from wholebody.control.controller import progress_report
from wholebody.control.log import concatenate
from wholebody.control.metrics import closed_chain_error, tracking
from wholebody.dynamics import DynamicsSolver
from wholebody.dynamics.controller import TorqueLog
from wholebody.errors import ConfigError, DataError, FrameError
from wholebody.files import read_npz
from wholebody.planning import obstacles as ob
from wholebody.planning.demonstration import align_to_chord
from wholebody.planning.dmp import DMP, DMPConfig, DMPTrajectory
from wholebody.planning.dual_arm import CoordinatedTrajectory
from wholebody.planning.trajectory import (
    HoldTrajectory,
    MinimumJerkTrajectory,
    Trajectory,
    minimum_jerk_scaling,
)
from wholebody.presets import default_stiffness, paper_stack
from wholebody.robot import Frame, Robot, RobotState, load_robot
from wholebody.robot.sim import SimSettings
from wholebody.scenarios.physics import (
    physics_metrics,
    physics_poses,
    physics_records,
    true_tracking,
)
from wholebody.scenarios.spec import ObjectSpec, PhaseSpec, ScenarioSpec
from wholebody.scenarios.standing import squeeze_errors, torque_arrays, torque_metrics
from wholebody.scenarios.torque_run import Grasp, balanced, torque_phase, torque_solver
from wholebody.solvers import ProjectionSolver, Solver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import ArmPotentialEnergy, CollisionAvoidance, FrameTask, RelativeFrameTask

__all__ = [
    "ScenarioRun",
    "closest_approach",
    "collision_model",
    "make_solver",
    "obstacle_of",
    "run_scenario",
    "scenario_robot",
    "start_configuration",
]


@dataclass
class ScenarioRun:
    """The outcome of :func:`run_scenario`."""

    spec: ScenarioSpec
    backend: str
    log: RunLog
    metrics: dict
    object_poses: dict[str, np.ndarray] = field(default_factory=dict)  # (N, 4, 4) each
    wall_time: float = 0.0
    physics: dict | None = None
    """A physics run's records (:meth:`wholebody.sim.PhysicsLog.arrays`), else None."""
    torque: dict[str, np.ndarray] | None = None
    """A torque-level run's torques and wrenches
    (:func:`~wholebody.scenarios.standing.torque_arrays`), else None."""


def make_solver(backend: str, engine: str | None = None) -> Solver:
    """The solver of a backend name (``projection``, ``pinv``, ``hqp``); ``engine``: the
    hierarchical QP's QP engine (``daqp`` by default, ``proxsuite``, ``osqp`` or any
    qpsolvers engine; only for ``hqp``)."""
    if backend in ("projection", "pinv"):
        if engine is not None:
            raise ConfigError(f"engine {engine!r} is for the hqp backend, not {backend!r}")
        return ProjectionSolver()
    if backend == "hqp":
        return HierarchicalQPSolver() if engine is None else HierarchicalQPSolver(engine)
    raise ConfigError(f"unknown backend {backend!r}: expected projection, pinv or hqp")


def scenario_robot(spec: ScenarioSpec) -> Robot:
    """The scenario's robot: a robot directory (or ``robot.toml``) beside the scenario file,
    else a bundled name (a directory there without a ``robot.toml`` does not hide it)."""
    candidate = spec.path.parent / spec.robot
    usable = candidate.is_file() or (candidate / "robot.toml").is_file()
    return load_robot(candidate if usable else spec.robot)


def start_configuration(spec: ScenarioSpec, robot: Robot) -> np.ndarray:
    """The configuration a run of ``spec`` starts from (``[scenario] start``): the robot's home
    posture, its neutral one, or the home posture with the named joints moved (rad, m), the
    base at the world origin. A :class:`ConfigError` naming the file and the joint for a
    joint the robot does not have (or a base actuator) and for a position outside the
    joint's limits."""
    if spec.start == "home":
        return robot.home()
    if spec.start == "neutral":
        return robot.neutral()
    if isinstance(spec.start, str):
        raise spec.error(
            "scenario.start",
            f'expected "home", "neutral" or a table of joint positions, got {spec.start!r}',
        )
    base = len(robot.base.actuators)
    joints = robot.actuated_joints[base:]
    positions = dict(zip(joints, robot.joint_positions(robot.home())[base:], strict=True))
    lower, upper = robot.position_limits
    for name, value in spec.start.items():
        key = f"scenario.start.{name}"
        if name in robot.actuated_joints[:base]:
            raise spec.error(
                key, f"{name!r} is a base actuator; the base starts at the world origin"
            )
        try:
            k = robot.index(name)
        except FrameError as exc:
            raise spec.error(key, f"unknown joint: {exc}") from None
        if not lower[k] <= value <= upper[k]:
            raise spec.error(
                key, f"{value} (rad or m) is outside the joint's limits [{lower[k]}, {upper[k]}]"
            )
        positions[name] = value
    return robot.configuration(positions)


def _stiffness(spec: ScenarioSpec, robot: Robot) -> float | StiffnessModel:
    return default_stiffness(robot) if spec.stack.stiffness == "learned" else spec.stack.stiffness


def _goal_pose(start: np.ndarray, goal: tuple[float, ...] | None, rotate) -> np.ndarray:
    T = start.copy()
    if goal is not None:
        T[:3, 3] = goal
    T[:3, :3] = pin.exp3(np.asarray(rotate, dtype=float)) @ start[:3, :3]
    return T


class _Planners:
    """Builds each phase's references (the DMP is learned once)."""

    def __init__(self, spec: ScenarioSpec) -> None:
        self.spec = spec
        self._dmp = None
        self._demo: tuple[np.ndarray, np.ndarray] | None = None

    def dmp(self, shape: str = "demo", chord: tuple[np.ndarray, np.ndarray] | None = None):
        """The scenario's DMP (``shape="demo"``), or one fitted on ``chord = (start, goal)``
        to the demonstration carried onto it (``"aligned"``) or to a minimum-jerk straight
        line on the demonstration's time grid (``"straight"``)."""
        if self._demo is None:
            z = read_npz(self.spec.planner.demo, "DMP demonstration")
            missing = [k for k in ("positions", "times") if k not in z]
            if missing:
                raise DataError(
                    f"{self.spec.planner.demo}: DMP demonstration lacks {', '.join(missing)}"
                )
            self._demo = (z["positions"], z["times"])
        positions, times = self._demo
        config = DMPConfig(n_basis=self.spec.planner.n_basis, stiffness=self.spec.planner.stiffness)
        if shape == "aligned":
            return DMP.fit(align_to_chord(positions, *chord), times, config=config)
        if shape == "straight":
            s, _, _ = minimum_jerk_scaling((times - times[0]) / (times[-1] - times[0]))
            start, goal = chord
            return DMP.fit(start + np.outer(s, goal - start), times, config=config)
        if self._dmp is None:
            self._dmp = DMP.fit(positions, times, config=config)
        return self._dmp

    def obstacles(self, names: tuple[str, ...]):
        out = []
        for name in names:
            o = self.spec.objects[name]
            if o.kind == "cylinder":
                shape = ob.cylinder(o.position, o.radius, o.height, margin=o.margin)
            elif o.kind == "sphere":
                shape = ob.sphere(o.position, o.radius, margin=o.margin)
            else:
                shape = ob.box(o.position, o.size, margin=o.margin)
            out.append(ob.DynamicPotential(shape))
        return out

    def phase(self, phase: PhaseSpec, starts: dict[str, np.ndarray]) -> dict[str, Trajectory]:
        refs: dict[str, Trajectory] = {}
        order = sorted(phase.hands, key=lambda h: phase.hands[h].planner == "follow")
        for hand in order:
            hp = phase.hands[hand]
            T0 = starts[hand]
            if hp.planner == "free":
                continue
            if hp.planner == "hold":
                refs[hand] = HoldTrajectory(T0, phase.duration)
            elif hp.planner == "min_jerk":
                refs[hand] = MinimumJerkTrajectory(
                    T0, _goal_pose(T0, hp.goal, hp.rotate), phase.duration
                )
            elif hp.planner == "dmp":
                goal = _goal_pose(T0, hp.goal, hp.rotate)
                refs[hand] = DMPTrajectory(
                    self.dmp(hp.shape, (T0[:3, 3], goal[:3, 3])),
                    T0,
                    goal,
                    phase.duration,
                    obstacles=self.obstacles(hp.avoid),
                )
            else:  # follow the primary through the grasp transform fixed now
                P0 = starts[phase.primary]
                refs[hand] = CoordinatedTrajectory(
                    refs[phase.primary], np.eye(4), np.linalg.solve(T0, P0)
                )
        return refs


def run_scenario(
    spec: ScenarioSpec,
    *,
    backend: str | None = None,
    progress: bool = False,
    on_step: Callable[[int, float, np.ndarray], None] | None = None,
    duration_scale: float = 1.0,
    sim: str = "kinematic",
    sim_settings: SimSettings | None = None,
    on_objects: Callable[[dict[str, np.ndarray]], None] | None = None,
    engine: str | None = None,
    sensor: JointSensor | None = None,
    latency: int | None = None,
) -> ScenarioRun:
    """Run every phase of a scenario with a backend (default: the scenario's).

    ``on_step(k, t, q)`` is called after every control step (live visualisation).
    ``duration_scale`` shortens or stretches every phase (tests use it to run quickly).
    ``sim``: ``"kinematic"`` (the commands integrated exactly) or ``"mujoco"`` (physics:
    :class:`wholebody.sim.MujocoPlant`, with ``sim_settings`` or the robot's ``[sim]``; the
    carried objects welded to their hands, both hands of a closed chain; a run the plant
    stops ends there, its reason in ``metrics["stopped"]``); ``on_objects(poses)`` is called
    after every step of a physics run with the free objects' poses (4x4, world).
    ``engine``: the hierarchical QP's QP engine (:func:`make_solver`). ``sensor``: what the
    controller of a physics run reads of the plant (:class:`~wholebody.control.JointSensor`:
    encoder noise, rad or m, and a delay of whole control periods); the log then holds what
    it saw, and ``metrics`` the hands and chain on the true state too
    (:func:`~wholebody.scenarios.physics.true_tracking`) and ``metrics["sensor"]``.
    ``latency``: the control periods by which the controller advances what it reads
    (:class:`~wholebody.control.Controller`'s state predictor); default the sensor's delay
    (a controller knows its own latency), 0 to leave the delay uncompensated.
    """
    backend = backend or spec.backend
    robot = scenario_robot(spec)
    plant = _plant(spec, robot, sim, sim_settings, sensor)
    latency = (sensor.delay if sensor is not None else 0) if latency is None else latency
    weights = spec.stack
    stiffness = _stiffness(spec, robot)
    for hand in spec.hands.values():
        robot.frame(hand.frame)  # fail early on a bad frame name
    tasks = {h: FrameTask(robot, s.frame, name=h, kp=s.kp, ki=s.ki) for h, s in spec.hands.items()}
    monitors = [ArmPotentialEnergy(robot, arm, stiffness) for arm in robot.arms]
    collision, collision_model = _collision(spec, robot)
    held: dict[str, tuple[str, np.ndarray]] = {}  # carried object -> (frame, pose there)
    phase_models: list[tuple[str, CollisionModel]] = []
    solver, dt = _solver(spec, robot, backend, engine)
    planners = _Planners(spec)
    shared = _Phase(spec, robot, solver, plant, latency, monitors)
    q = start_configuration(spec, robot)
    if plant is not None:
        plant.reset(q)
    state = robot.update(q)
    starts = {h: state.pose(t.frame) for h, t in tasks.items()}
    logs, start_wall, t0 = [], time.perf_counter(), 0.0
    steps = [max(1, round(p.duration * duration_scale / dt)) for p in spec.phases]
    bar = _progress_bar(sum(steps), spec.name) if progress else None
    carries: dict[str, list[tuple[str, float, float]]] = {}  # object -> (hand, start, end)
    phases: dict[str, list[float]] = {}  # name -> [start, end] (s)
    for phase, n in zip(spec.phases, steps, strict=True):
        duration = n * dt
        phases[phase.name] = [t0, t0 + duration]
        refs = planners.phase(_scaled(phase, duration), starts)
        entries = [tasks[h] for h in refs]
        first = _chain(robot, phase, tasks, starts)
        phase_collision, phase_model = collision, collision_model
        if spec.collision is not None:
            phase_collision, phase_model = _carrying(
                spec, robot, phase, state, tasks, held, collision, collision_model
            )
        stack = paper_stack(
            robot,
            entries,
            objectives=backend != "pinv",
            weights=weights,
            stiffness=stiffness,
            first=first,
            acceleration=weights.acceleration and backend != "dynamics",
            collision=phase_collision,
        )
        stack = balanced(robot, stack, q, spec.torque.com_kp)  # (a floating base's balance)
        if plant is not None:
            plant.hold(_grips(phase, tasks))
        if bar is not None:
            bar.set_postfix_str(phase.name)
        objects = on_objects if plant is not None else None
        callback = _callback(bar, on_step, objects, plant, t0, sum(len(x) for x in logs))
        log = _run_phase(
            shared,
            stack,
            {tasks[h]: r for h, r in refs.items()},
            q,
            duration,
            callback,
            {"phase": phase.name},
            _final_u(logs[-1]) if logs else None,
            t0,
            _grasp(phase, tasks, shared),
        )
        logs.append(log)
        q = np.asarray(log.meta["final_q"])
        if phase_model is not None:
            phase_models.append((phase.name, phase_model))
        state = robot.update(q)
        starts = {
            h: refs[h].end_pose if h in refs else state.pose(t.frame) for h, t in tasks.items()
        }
        for hand, hp in phase.hands.items():
            if hp.carry is not None:
                carries.setdefault(hp.carry, []).append((hand, t0, t0 + duration))
        t0 += duration
        if "stopped" in log.meta:
            break
    if bar is not None:
        bar.close()
    log = concatenate(
        logs,
        {
            "phases": phases,
            "scenario": spec.name,
            "backend": backend,
            "start": spec.start,
            "sim": sim,
        },
    )
    metrics = _metrics(log, spec, duration_scale)
    metrics["sim"], metrics["stopped"] = sim, logs[-1].meta.get("stopped")
    frames = {h: tasks[h].frame for h in tasks}
    if plant is None:
        poses, physics = _object_poses(robot, log, spec.objects, carries, frames), None
    else:
        poses, physics = _physics_outcome(spec, robot, plant, log, frames, metrics, latency)
    if collision_model is not None:
        masks = [(model, log.phase_mask(name)) for name, model in phase_models]
        metrics.update(closest_approach(masks, log, spec.collision.safety))
        metrics["collision_pairs"] = collision_model.summary()
    torque = _torque_outcome(shared, log, physics, metrics)
    wall = time.perf_counter() - start_wall
    if plant is not None:  # simulated time per wall second, the controller's time included
        metrics["real_time_factor"] = len(log) * dt / wall
    return ScenarioRun(spec, backend, log, metrics, poses, wall, physics, torque)


def _solver(
    spec: ScenarioSpec, robot: Robot, backend: str, engine: str | None
) -> tuple[Solver | DynamicsSolver, float]:
    """The run's solver and control period (s): ``[torque]``'s for ``dynamics``."""
    if backend != "dynamics":
        return make_solver(backend, engine), spec.dt
    if engine is not None:
        raise ConfigError(f"engine {engine!r} is for the hqp backend, not dynamics")
    return torque_solver(spec, robot), spec.torque.dt


@dataclass
class _Phase:
    """What every phase of a run shares."""

    spec: ScenarioSpec
    robot: Robot
    solver: Solver | DynamicsSolver
    plant: object
    latency: int
    monitors: list
    torque: list[TorqueLog] = field(default_factory=list)
    """The torque-level phases' torques and wrenches, in order."""
    offsets: dict[str, np.ndarray] = field(default_factory=dict)
    """Carried object -> its pose in its first hand's frame as last held (torque level)."""


def _run_phase(
    p: _Phase,
    stack: Stack,
    refs: dict[FrameTask, Trajectory],
    q: np.ndarray,
    duration: float,
    callback: Callable[[int, float, np.ndarray], None],
    meta: dict,
    u0: np.ndarray | None,
    t0: float,
    grasp: Grasp,
) -> RunLog:
    """One phase's run: the velocity controller, or the torque-level one (``dynamics``,
    carrying what ``grasp`` holds)."""
    if isinstance(p.solver, DynamicsSolver):
        log, torques = torque_phase(
            p.spec,
            p.robot,
            stack,
            p.solver,
            refs,
            p.plant,
            q,
            duration,
            t0=t0,
            u0=u0,
            monitors=p.monitors,
            callback=callback,
            meta=meta,
            grasp=grasp,
        )
        p.torque.append(torques)
        return log
    controller = Controller(
        p.robot,
        stack,
        p.solver,
        dt=p.spec.dt,
        references=refs,
        monitors=p.monitors,
        plant=p.plant,  # type: ignore[arg-type]
        latency=p.latency,
    )
    return controller.run(q, duration, callback=callback, meta=meta, u0=u0)


def _torque_outcome(
    shared: _Phase, log: RunLog, physics: dict | None, metrics: dict
) -> dict[str, np.ndarray] | None:
    """A torque-level run's records, its metrics added to ``metrics``
    (:mod:`wholebody.scenarios.standing`); None for a velocity-level run."""
    if not shared.torque:
        return None
    torque = torque_arrays(shared.torque)
    metrics.update(
        torque_metrics(
            shared.robot,
            shared.solver,  # type: ignore[arg-type]
            torque,
            log.q if physics is None else physics["configuration"],
            log.t,
            shared.spec.torque.pushes if shared.plant is not None else (),
            bool(metrics.get("stopped")),
        )
    )
    setpoints = [
        (log.phase_mask(p.name), p.squeeze_n)
        for p in shared.spec.phases
        if p.squeeze_n is not None and p.name in log.meta["phases"]
    ]
    if setpoints:
        squeeze = {k.split("/", 1)[1]: v for k, v in torque.items() if k.startswith("squeeze/")}
        if physics is not None:  # what the welds measured, where the controller held it
            squeeze = {
                o: np.where(np.isfinite(s), physics["squeeze"][o], np.nan)
                for o, s in squeeze.items()
                if o in physics["squeeze"]
            }
        metrics["squeeze_error_max_n"] = squeeze_errors(setpoints, squeeze)
    return torque


def _grasp(phase: PhaseSpec, tasks: dict[str, FrameTask], shared: _Phase) -> Grasp:
    """What ``phase`` carries for the torque level: each object with its hands' frames, the
    chain's primary first."""
    carried: dict[str, list[str]] = {}
    for hand, obj in sorted(_carried(phase).items(), key=lambda ho: ho[0] != phase.primary):
        carried.setdefault(obj, []).append(tasks[hand].frame.name)
    return Grasp({o: tuple(h) for o, h in carried.items()}, phase.squeeze_n, shared.offsets)


def _final_u(log: RunLog) -> np.ndarray:
    """The velocity a phase ends with: the torque run's measured one, else the last
    command."""
    return np.asarray(log.meta["final_u"]) if "final_u" in log.meta else log.u[-1]


def _chain(
    robot: Robot, phase: PhaseSpec, tasks: dict[str, FrameTask], starts: dict[str, np.ndarray]
) -> list[RelativeFrameTask]:
    """A closed-chain phase's relative pose task (the secondary hand in the primary's frame,
    held where the phase starts), for a level above the hands: the grasp is never traded."""
    if not phase.closed_chain:
        return []
    secondary = next(h for h in phase.hands if h != phase.primary)
    chain = RelativeFrameTask(
        robot,
        tasks[phase.primary].frame,
        tasks[secondary].frame,
        name="closed_chain",
        kp=tasks[phase.primary].kp[0],
    )
    chain.set_target(np.linalg.solve(starts[phase.primary], starts[secondary]))
    return [chain]


def _callback(bar, on_step, on_objects, plant, offset: float, done: int):
    """A phase's step callback: the progress bar, ``on_step`` with the run's step and time,
    and ``on_objects`` with the plant's objects (a physics run)."""

    def callback(k: int, t: float, q: np.ndarray) -> None:
        if bar is not None:
            bar.update(1)
        if on_objects is not None:  # before on_step: the frame it draws shows them
            on_objects(plant.object_poses())
        if on_step is not None:
            on_step(done + k, offset + t, q)

    return callback


def _physics_outcome(
    spec: ScenarioSpec,
    robot: Robot,
    plant,
    log: RunLog,
    frames: dict[str, Frame],
    metrics: dict,
    latency: int,
) -> tuple[dict, dict]:
    """A physics run's object poses and records; its metrics added to ``metrics`` (read
    through a sensor: the true state's tracking and ``sensor`` too)."""
    physics = physics_records(plant, log, frames)
    metrics.update(physics_metrics(plant, physics))
    if not plant.sensor.exact:
        metrics["sensor"] = {**plant.sensor.describe(), "latency_compensated_periods": latency}
        metrics.update(
            true_tracking(robot, log, physics["configuration"], frames, _chains(spec, log, frames))
        )
    return physics_poses(spec.objects, physics), physics


def _chains(spec: ScenarioSpec, log: RunLog, frames: dict[str, Frame]) -> list:
    """Per closed-chain phase that ran: its steps' mask, the primary's and the secondary's
    frames."""
    out = []
    for phase in spec.phases:
        if phase.closed_chain and phase.name in log.meta["phases"]:
            secondary = next(h for h in phase.hands if h != phase.primary)
            out.append((log.phase_mask(phase.name), frames[phase.primary], frames[secondary]))
    return out


def _plant(
    spec: ScenarioSpec,
    robot: Robot,
    sim: str,
    settings: SimSettings | None,
    sensor: JointSensor | None = None,
):
    """The physics plant of a ``sim="mujoco"`` run (None for ``"kinematic"``), with a weld
    for every (object, hand) a phase carries, read through ``sensor``."""
    if sensor is not None and not isinstance(sensor, JointSensor):
        raise ConfigError(f"sensor must be a wholebody.control.JointSensor, got {sensor!r}")
    if sim == "kinematic":
        if sensor is not None and not sensor.exact:
            raise ConfigError(
                "a sensor model (noise, delay) reads a simulated plant: it needs "
                "sim='mujoco' (--sim mujoco)"
            )
        return None
    if sim != "mujoco":
        raise ConfigError(f"unknown sim {sim!r}: expected 'kinematic' or 'mujoco'")
    try:
        from wholebody.sim import MujocoPlant
    except ImportError as exc:  # the sim extra
        raise ConfigError(
            f'physics runs need MuJoCo: pip install "wholebody[sim]" ({exc})'
        ) from None
    frames = {h: s.frame for h, s in spec.hands.items()}
    grasps = {(o, frames[h]) for phase in spec.phases for h, o in _carried(phase).items()}
    return MujocoPlant(
        robot, spec.objects.values(), sorted(grasps), settings or robot.sim_settings, sensor
    )


def _carried(phase: PhaseSpec) -> dict[str, str]:
    """Hand -> the object it holds in ``phase``: the hand whose ``carry`` names it and, in a
    closed-chain phase, the chain's other hand too (both hands grip a carried panel)."""
    held = {h: hp.carry for h, hp in phase.hands.items() if hp.carry}
    if phase.closed_chain and held:
        obj = next(iter(held.values()))
        held.update({h: obj for h in phase.hands if h not in held})
    return held


def _grips(phase: PhaseSpec, tasks: dict[str, FrameTask]) -> list[tuple[str, str]]:
    """The (object, hand frame) welds on during ``phase``."""
    return [(obj, tasks[h].frame.name) for h, obj in _carried(phase).items()]


def _collision(
    spec: ScenarioSpec,
    robot: Robot,
    attached: Sequence[tuple[str, Obstacle]] = (),
    start: np.ndarray | None = None,
) -> tuple[CollisionAvoidance | None, CollisionModel | None]:
    """The scenario's ``[collision]``: the constraint (None unless enforced) and the model
    whose closest approach the metrics report (None without the section); ``attached`` and
    ``start`` as :class:`~wholebody.collision.CollisionModel` takes them (a carry)."""
    cs = spec.collision
    if cs is None:
        return None, None
    obstacles = [obstacle_of(spec.objects[name]) for name in cs.obstacles]
    model = CollisionModel(
        robot,
        obstacles,
        safety=cs.safety,
        self_collision=cs.self_collision,
        attached=attached,
        start=start,
    )
    if not cs.enforce:
        return None, model
    task = CollisionAvoidance(
        robot, model, safety=cs.safety, influence=cs.influence, speed=cs.speed
    )
    return task, model


def _carrying(
    spec: ScenarioSpec,
    robot: Robot,
    phase: PhaseSpec,
    state: RobotState,
    tasks: dict[str, FrameTask],
    held: dict[str, tuple[str, np.ndarray]],
    collision: CollisionAvoidance | None,
    model: CollisionModel,
) -> tuple[CollisionAvoidance | None, CollisionModel | None]:
    """The phase's collision task and model: the scenario's, or with the objects the phase
    carries attached to their hands (their pose relative to the hand taken where the carry
    starts, the grasp's contacts left out), so that the arms keep off a carried panel."""
    carried = [(h, hp.carry) for h, hp in phase.hands.items() if hp.carry]
    if not carried:
        held.clear()
        return collision, model
    attached = []
    for hand, name in carried:
        frame = tasks[hand].frame
        if name not in held:
            held[name] = (frame.name, np.linalg.solve(state.pose(frame), spec.objects[name].pose))
        obj = obstacle_of(spec.objects[name])
        attached.append((held[name][0], Obstacle(obj.name, obj.shape, obj.size, held[name][1])))
    return _collision(spec, robot, attached, state.q)


def collision_model(spec: ScenarioSpec, robot: Robot) -> CollisionModel | None:
    """The scenario's collision shapes and pairs (None without ``[collision]``)."""
    return _collision(spec, robot)[1]


def obstacle_of(obj: ObjectSpec) -> Obstacle:
    """A scenario object as a fixed collision shape (centre at its position, axes the
    world's; a cylinder along z)."""
    sizes = {"box": tuple(obj.size), "cylinder": (obj.radius, obj.height), "sphere": (obj.radius,)}
    return Obstacle(obj.name, obj.kind, sizes[obj.kind], obj.pose)


def closest_approach(
    models: Sequence[tuple[CollisionModel, np.ndarray]],
    log: RunLog,
    safety: float,
    within: float = 0.1,
) -> dict:
    """``min_collision_distance_m`` over every logged step and checked pair, with the pair,
    the time (s) and its witness points (m, world), and ``collision_limited``: per pair held
    at the safety distance (within 1 mm of it), the tasks more than 1 mm (or rad) off their
    target at those steps, and how many steps (a correlation, not the solver's attribution).
    ``models``: each phase's model (carried objects attached) with its steps' mask. Pairs
    farther than ``within`` (m) are skipped by the bounding spheres; if none comes that
    close, every pair is measured on every 10th step."""
    best: tuple[float, PairDistance | None, float] = (math.inf, None, 0.0)
    limited: dict[tuple[str, str], int] = {}
    owner = np.zeros(len(log), dtype=int)
    for m, (_, mask) in enumerate(models):
        owner[mask] = m
    for stride, limit in ((1, within), (10, math.inf)):
        for k in range(0, len(log), stride):
            model = models[owner[k]][0]
            for pair in model.distances(model.robot.update(log.q[k]), limit):
                if pair.distance < best[0]:
                    best = (pair.distance, pair, float(log.t[k]))
                if pair.distance <= safety + 1e-3:
                    for task in _unmet(log, k):
                        limited[(pair.name, task)] = limited.get((pair.name, task), 0) + 1
        if math.isfinite(best[0]):
            break
    pair = best[1]
    return {
        "min_collision_distance_m": pair.distance if pair else None,
        "min_collision_pair": pair.name if pair else "",
        "min_collision_time_s": best[2],
        "min_collision_points_m": [pair.point_a.tolist(), pair.point_b.tolist()] if pair else None,
        "collision_limited": [
            {"pair": p, "task": t, "steps": n} for (p, t), n in sorted(limited.items())
        ],
    }


def _unmet(log: RunLog, k: int, tol: float = 1e-3) -> list[str]:
    """The tasks more than ``tol`` off at step ``k``."""
    return [name for name, e in log.task_errors.items() if np.linalg.norm(e[k]) > tol]


def _progress_bar(total: int, name: str):
    """The run's progress: a bar on a terminal, plain lines in a log (never a bar there)."""
    return progress_report(total, True, name, leave=True)


def _scaled(phase: PhaseSpec, duration: float) -> PhaseSpec:
    if duration == phase.duration:
        return phase
    return PhaseSpec(phase.name, duration, phase.hands, phase.closed_chain, phase.primary)


def _object_poses(
    robot: Robot,
    log: RunLog,
    objects: dict[str, ObjectSpec],
    carries: dict[str, list[tuple[str, float, float]]],
    frames,
) -> dict[str, np.ndarray]:
    """(N, 4, 4) pose of every object: rigid with its hand during each carrying phase
    ``(hand, start, end)``, and where it was left before and after."""
    out = {}
    n = len(log)
    for name, obj in objects.items():
        T = obj.pose
        poses = np.empty((n, 4, 4))
        k = 0  # poses before k are written
        for hand, t_start, t_end in carries.get(name, ()):
            k0 = int(np.searchsorted(log.t, t_start - 1e-9))
            k1 = int(np.searchsorted(log.t, t_end - 1e-9))
            poses[k:k0] = T  # where it was left
            relative = np.linalg.solve(robot.frame_pose(log.q[k0], frames[hand]), T)
            for j in range(k0, k1):
                poses[j] = robot.frame_pose(log.q[j], frames[hand]) @ relative
            k = k1
            if k1 < n:  # left where the hand is at the phase's end (the next sample)
                T = robot.frame_pose(log.q[k1], frames[hand]) @ relative
            elif k1 > k0:
                T = poses[k1 - 1].copy()
        poses[k:] = T
        out[name] = poses
    return out


def _metrics(log: RunLog, spec: ScenarioSpec, duration_scale: float) -> dict:
    m = summary(log)
    m["scenario"] = spec.name
    m["backend"] = log.meta.get("backend")
    m["phases"] = {}
    chain_max = 0.0
    for phase in spec.phases:
        if phase.name not in log.meta["phases"]:  # a run stopped before it
            continue
        mask = log.phase_mask(phase.name)
        entry: dict = {"mae_m": {}, "mse_m2": {}}
        for hand, hp in phase.hands.items():
            if hp.planner == "free":
                continue
            tr = tracking(log, hand, mask)
            entry["mae_m"][hand] = tr.mae_m
            entry["mse_m2"][hand] = tr.mse_m2
        if phase.closed_chain:
            entry["closed_chain_error_max_m"] = closed_chain_error(log, "closed_chain", mask)
            chain_max = max(chain_max, entry["closed_chain_error_max_m"])
        m["phases"][phase.name] = entry
    m["closed_chain_error_max_m"] = chain_max
    m["duration_scale"] = duration_scale
    return m
