"""The control loop: references -> tasks -> solver -> integrate -> log.

One step at time ``t_k = k dt`` (:meth:`Controller.step`):

1. every referenced task gets its target: the reference pose at ``t_k`` and, as the
   paper's feed-forward ``x'_d``, the reference twist at the **mid-step** ``t_k + dt/2``.
   With ``u`` held for the step, the mid-step twist makes the commanded motion the secant
   of the reference to second order, so the tracking error does not lag by ``a dt / 2 Kp``
   as with the twist at ``t_k`` (set ``feedforward="start"`` for the latter). The references
   are sampled a block of steps at a time into a buffer the kernel reads;
2. the kinematics at ``q_k``, the stack's rows, the solver's ``u_k``;
3. the tasks' integrators advance, each with its own anti-windup (its integral stops
   growing while a bound limits that task: :meth:`Stack.saturated_tasks
   <wholebody.solvers.Stack.saturated_tasks>`; a joint no task moves may rest on its limit),
   and the limits with a memory keep ``u_k``;
4. ``q_{k+1} = integrate(q_k, u_k, dt)`` (exact on the configuration manifold).

Steps 2 to 4 are **one kernel call** (:mod:`wholebody.kernels.control`) when every entry of
the stack is compiled and the robot's joints are ones the kernels move (then the kernel
computes the kinematics too); an entry written in Python adds Pinocchio's kinematics and the
entry's own Python code around the call. :meth:`Controller.run` runs the loop with a log row
per step (errors, tracked positions against references, arm energies) and, with a ``plant``,
integrates by the configuration the plant reaches under ``u_k`` (a physics simulation).

``step_time`` is the wall time of the control computation of a step: steps 1 to 4, without
the log's own recording and monitoring (and without a plant's simulation).

A configuration measured ``latency`` control periods late (``Controller(latency=N)``, e.g.
a plant read through a :class:`~wholebody.control.JointSensor` with that delay) is first
brought to the present: integrated, exactly, by the controller's own last ``N`` commands
(a state predictor). Without it the feedback closes on a stale pose: a hand moving at ``v``
ends ``v N dt`` ahead of its reference (measured under physics: the carry's hands 9.6 mm
off at one period of 10 ms, against 3.0 mm without the delay).
"""

from __future__ import annotations

import contextlib
import gc
import math
import numbers
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import IO, Any, Protocol, runtime_checkable

import numpy as np
from threadpoolctl import threadpool_limits

from wholebody.control.batch import BatchResult, solve_many
from wholebody.control.log import ArmTrace, RunLog
from wholebody.control.recovery import StallRecovery
from wholebody.errors import DimensionError, WholebodyError
from wholebody.kernels import layout as lay
from wholebody.kernels.control import ADVANCE, INTEGRATE, KINEMATICS, NOT_FINITE, Batch
from wholebody.kernels.evaluate import REF_WIDTH
from wholebody.kernels.watch import pose_watch
from wholebody.planning.trajectory import Trajectory
from wholebody.robot import Robot, RobotState
from wholebody.solvers.base import Solver
from wholebody.solvers.plan import Plan
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import Stack
from wholebody.solvers.unmet import classify
from wholebody.tasks.arm_energy import ArmPotentialEnergy
from wholebody.tasks.base import Objective, Task
from wholebody.tasks.frame import FrameTask

__all__ = ["Controller", "Plant", "ReferenceTask"]

_F64 = np.dtype(np.float64)


@runtime_checkable
class Plant(Protocol):
    """What a controller's commands drive: ``step(q, u, dt)`` applies the actuated velocity
    ``u`` for ``dt`` seconds from ``q`` and returns the configuration reached (:meth:`Robot.
    integrate` is the exact kinematic one; :class:`wholebody.sim.MujocoPlant` is physics)."""

    def step(self, q: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray: ...


@runtime_checkable
class ReferenceTask(Protocol):
    """A task that follows a reference: it takes a target pose (4x4) and twist
    ``[v (m/s), w (rad/s)]`` every step. :class:`FrameTask` and :class:`RelativeFrameTask`
    are; a task of your own is by having this method."""

    name: str

    def set_target(self, pose: np.ndarray, twist: np.ndarray | None = None) -> None: ...


TargetTask = ReferenceTask


class Controller:
    """Runs a stack on a robot with a solver, tracking references.

    Parameters
    ----------
    robot, stack, solver
        What to control and how.
    dt
        Control period (s).
    references
        Trajectory per task of the stack that tracks one (:class:`ReferenceTask`: a
        :class:`FrameTask` follows it in the world, a :class:`RelativeFrameTask` in its first
        frame, a task of your own as its ``set_target`` says).
    monitors
        Objectives to log each step (by default none): an arm energy's terms
        (``RunLog.arms``), any other objective's value (``RunLog.objectives``). Give the same
        monitors to runs you want to compare, whatever their stacks.
    feedforward
        ``"midpoint"`` (default) or ``"start"``: when the reference twist is sampled.
    recovery
        Retreat to a ready posture when the pose tasks stall in a local minimum, then retry
        (:class:`~wholebody.control.recovery.StallRecovery`): True (default) watches every
        :class:`FrameTask` of the stack with the recovery's defaults (none if it has none), a
        :class:`StallRecovery` made for ``stack`` is used as it is, False turns it off. It
        acts only when a watched task has been unmet, its target at rest, for 0.15 s while
        the error shrank slower than the recovery's rates (``E / 1 s`` and 0.2 m/s); else it
        changes nothing. The run log's
        ``meta["retreats"]`` lists the retreats (``[start, end]`` in s; end None if the run
        ended during one).
    plant
        What the commands drive (default: the exact integration :meth:`Robot.integrate`):
        an object with ``step(q, u, dt) -> q`` returning the configuration reached, such as
        :class:`wholebody.sim.MujocoPlant` (physics), whose configuration the controller then
        reads. A plant whose ``stop_reason`` becomes a string ends the run after that step
        (the log holds the steps done; ``meta["stopped"]`` the reason).
    latency
        Control periods (a whole number >= 0, default 0) by which the configurations given
        to :meth:`step` and returned by the plant are late: each is advanced by the last
        ``latency`` commands before the step (module docstring); the log holds the advanced
        one, the configuration the step was computed at. The commands before the first step
        are taken as ``u0`` (:meth:`reset`), which is exact for one period.
    threads
        Threads of the BLAS and OpenMP libraries (numpy's, scipy's) while :meth:`run` runs
        the loop, restored after (threadpoolctl); None leaves the libraries' own setting.
        Default 1: a control step is many small products, which threads only slow down, and
        on a busy machine a step then waits for the other threads' cores (measured on a
        loaded 2-core machine: a 99-DOF robot's step took 720-780 ms with two OpenBLAS
        threads and 8-19 ms with one).
    """

    def __init__(
        self,
        robot: Robot,
        stack: Stack,
        solver: Solver,
        *,
        dt: float,
        references: Mapping[TargetTask, Trajectory] | None = None,
        monitors: Sequence[Objective] = (),
        feedforward: str = "midpoint",
        recovery: StallRecovery | bool | None = True,
        plant: Plant | None = None,
        latency: int = 0,
        threads: int | None = 1,
    ) -> None:
        if not dt > 0:
            raise DimensionError(f"control period dt must be > 0 s, got {dt}")
        if feedforward not in ("midpoint", "start"):
            raise WholebodyError(f"feedforward must be 'midpoint' or 'start', got {feedforward!r}")
        if not callable(getattr(solver, "solve", None)):
            raise WholebodyError(
                f"solver must be a solver object (ProjectionSolver(), HierarchicalQPSolver()), "
                f"got {solver!r}"
            )
        self.robot, self.stack, self.solver, self.dt = robot, stack, solver, float(dt)
        self.references = dict(references or {})
        stacked = set(map(id, stack.tasks))
        for task, traj in self.references.items():
            if not isinstance(task, ReferenceTask):
                raise WholebodyError(
                    f"references are keyed by the task object (a task of the stack with a "
                    f"set_target(pose, twist) method, e.g. a FrameTask), got the key {task!r}"
                )
            if not isinstance(traj, Trajectory):
                raise WholebodyError(
                    f"reference for task {task.name!r} must be a Trajectory (a DMPTrajectory, "
                    f"MinimumJerkTrajectory, ...; for a fixed pose call task.set_target), got "
                    f"{type(traj).__name__}"
                )
            if id(task) not in stacked:
                raise WholebodyError(
                    f"reference given for task {task.name!r}, which is not in the stack"
                )
        self.monitors = list(monitors)
        for m in self.monitors:
            if not isinstance(m, Objective):
                raise WholebodyError(
                    f"monitors are objectives (ArmPotentialEnergy, "
                    f"JointLimitAvoidance, ...), got {m!r}"
                )
        self.feedforward = feedforward
        self.recovery = _recovery(robot, stack, recovery)
        if plant is not None and not callable(getattr(plant, "step", None)):
            raise WholebodyError(
                f"plant must have step(q, u, dt) -> q (e.g. "
                f"wholebody.sim.MujocoPlant), got {plant!r}"
            )
        self.plant = plant
        if isinstance(latency, bool) or not isinstance(latency, numbers.Integral) or latency < 0:
            raise WholebodyError(
                f"latency must be a whole number >= 0 (control periods by "
                f"which the measured configuration is late), got "
                f"{latency!r}"
            )
        self.latency = int(latency)
        self._sent: deque[np.ndarray] = deque(maxlen=self.latency)
        self.threads = _thread_count(threads)

        self._k = 0
        self._refs: np.ndarray | None = None  # (block, nR, REF_WIDTH) samples of the references
        self._python_refs: list[tuple[int, ReferenceTask]] = []  # (index, task) set in Python
        self._bound: Plan | None = None  # the plan the references are bound to
        self._plan: Plan | None = None  # the plan of the last step
        self._fast = False
        self._call: Callable[[], None] | None = None  # the kernel call of a step (bound)
        self._batch: Batch | None = None  # its batch
        self._limits: object | None = None
        self._plan_of_step: Plan | None = None
        # pose_watch's arguments for the stack's plan: the arena's F_PAR, the recovery's
        # tasks' blocks in it, the plan's flags of tasks unmet and the tasks' rows in them
        self._watch: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._main: Plan | None = None  # that plan
        self._u = np.zeros(robot.nu)
        self._q_next = np.zeros(robot.nq)
        self.solve_time = 0.0
        """Wall time (s) of the last step's kernel call (or calls)."""

    # ------------------------------------------------------------------ one step
    @property
    def t(self) -> float:
        """The time (s) of the next step: ``k dt`` after :meth:`reset`."""
        return self._k * self.dt

    def reset(self, u0: np.ndarray | None = None) -> None:
        """Start again at t = 0: the tasks' integrals, the limits' memory (the velocity the
        robot has now, ``u0``, default at rest) and a recovery forgotten."""
        self.stack.reset()
        if self.recovery is not None:
            self.recovery.reset()
        self._k = 0
        self._refs = None
        if u0 is not None:
            u0 = np.asarray(u0, dtype=float)
            if u0.shape != (self.robot.nu,) or not np.isfinite(u0).all():
                raise DimensionError(f"u0 must be {self.robot.nu} finite velocities, got {u0!r}")
            self.stack.set_velocity(u0, self.dt)
        sent = np.zeros(self.robot.nu) if u0 is None else u0.copy()
        self._sent.extend([sent] * self.latency)

    def _present(self, q: np.ndarray) -> np.ndarray:
        """``q`` measured ``latency`` periods ago, advanced by the commands sent since (the
        last ``latency`` steps' ``u``, exact integration); ``q`` itself without latency."""
        for u in self._sent:
            q = self.robot.integrate(q, u, self.dt)
        return q

    def step(self, q: np.ndarray) -> np.ndarray:
        """One control step at the configuration ``q`` (measured, or the last
        :attr:`q_next`): the actuated velocity ``u`` (rad/s, m/s; a new array) to apply for
        ``dt`` seconds. The references are read at :attr:`t`, the tasks' integrators and the
        limits' memory advance, and :attr:`q_next` is the configuration ``u`` reaches
        (exact integration). :attr:`result` reports the solve.

        The BLAS threads are limited to ``threads`` from the first step on (threadpoolctl),
        until :meth:`close`."""
        if self._limits is None and self.threads is not None:
            self._limits = threadpool_limits(self.threads)
        q = self._checked(self._present(q) if self.latency else q)
        self._step(q, None)
        if self.latency:
            self._sent.append(self._u.copy())
        return self._u.copy()

    @property
    def q_next(self) -> np.ndarray:
        """The configuration the last step's ``u`` reaches in ``dt`` (a view, overwritten by
        the next step)."""
        if self._plan is None:
            raise WholebodyError("Controller.q_next: no step was taken yet")
        return self._q_next

    @property
    def result(self) -> SolverResult:
        """The last step's solve as a :class:`SolverResult` (made when asked for);
        ``print(controller.result)`` tells it in words until the next step
        (:meth:`SolverResult.report`)."""
        plan = self._plan
        if plan is None:
            raise WholebodyError("Controller.result: no step was taken yet")
        if plan.last_result is None:
            plan.last_result = self.solver.result(plan, self.solve_time, self.stack)
        return plan.last_result

    def step_many(
        self,
        Q: np.ndarray,
        targets: Mapping[Task, np.ndarray] | None = None,
        *,
        steps: int = 1,
        threads: int | None = None,
    ) -> BatchResult:
        """Solve ``N`` independent states of the stack in one kernel call per thread
        (:mod:`wholebody.control.batch`): each from its configuration ``Q[n]`` (N x nq), the
        pose tasks in ``targets`` going to their poses ``targets[task][n]`` (N x 4 x 4),
        ``steps`` control steps each (a closed-loop reach inside the kernel), on ``threads``
        threads (default: every core). The stack's own state (integrals, memories) is the
        start of every state and is left unchanged. Needs every entry compiled, and daqp for
        the HQP."""
        with _threads(1):  # one BLAS thread in each of the batch's threads
            return solve_many(self, Q, targets, steps, threads)

    def close(self) -> None:
        """Give the BLAS threads back (what :meth:`step` limited)."""
        if self._limits is not None:
            self._limits.restore_original_limits()  # type: ignore[attr-defined]
            self._limits = None

    def _checked(self, q: np.ndarray) -> np.ndarray:
        """``q`` as the kernel takes it: nq numbers (whether they are finite is checked by
        the step: by the kernel where the step is one call, see :meth:`_not_finite`)."""
        if q.__class__ is not np.ndarray or q.dtype is not _F64 or q.shape != self._q_next.shape:
            q = self.robot.check_configuration(q)
        return q

    def _not_finite(self, q: np.ndarray) -> DimensionError:
        """The error for a configuration that is not finite (the step then wrote nothing)."""
        return DimensionError(f"configuration of robot {self.robot.name!r} is not finite: {q}")

    def _call_step(self, q: np.ndarray, state: RobotState | None) -> None:
        """:meth:`_step` where the last step was one kernel call on the same plan: the same
        call again (:meth:`Solver.stepper <wholebody.solvers.base.Solver.stepper>`)."""
        plan = self._bound
        j = self._k % _BLOCK
        if j == 0:
            self._sample(self._k)
        batch = self._batch
        batch.Q[0] = q
        if self.references:
            batch.refs[0] = self._refs[j]  # type: ignore[index]
        start = time.perf_counter()
        plan.sync(state, self.dt)  # type: ignore[union-attr]
        if plan.stale:  # type: ignore[union-attr]
            self._bound = self._call = None
            return self._step(q, state)
        self._call()  # type: ignore[misc]
        if batch.status[0] == NOT_FINITE:
            raise self._not_finite(q)
        self.solve_time = time.perf_counter() - start
        plan.evaluated = -1.0 if state is None else state.stamp  # type: ignore[union-attr]
        plan.last_result = None  # type: ignore[union-attr]
        self._observe(q)
        self._k += 1

    def _active(self) -> Stack:
        """The stack to solve at this step: the controller's, or its recovery's retreat."""
        return self.stack if self.recovery is None else self.recovery.stack

    def _step(self, q: np.ndarray, state: RobotState | None) -> None:
        """The step of :meth:`step` (module docstring), ``state`` the kinematics at ``q`` if
        the caller has them."""
        if self._call is not None and self._active().plan() is self._bound:
            return self._call_step(q, state)
        if not math.isfinite(q.dot(q)):
            raise self._not_finite(q)
        rec = self.recovery
        plan = self._active().plan()
        if plan is not self._bound:
            self._bind(plan)
        j = self._k % _BLOCK
        if j == 0 or self._refs is None:
            self._sample(self._k - j)
        buffers = plan.step_buffers(len(self.references))
        batch = buffers.batch
        batch.Q[0] = q
        if self.references:
            batch.refs[0] = self._refs[j]  # type: ignore[index]
        start = time.perf_counter()
        fast = self._fast
        if fast:
            plan.sync(state, self.dt)
            if plan.stale:  # an entry changed shape: lay the stack out anew, then step
                self._bound = None
                return self._step(q, state)
            what = KINEMATICS | ADVANCE | INTEGRATE
            self.solver.run(plan, buffers.own, batch, 1, what)
            plan.evaluated = -1.0 if state is None else state.stamp
            self._call = self.solver.stepper(plan, buffers.own, batch, what)  # the next steps'
            self._batch = batch
        else:
            state = self._general(plan, q, state, j)
            plan = self._plan_of_step
        self.solve_time = time.perf_counter() - start
        plan.last_result = None
        batch = plan.step_buffers(len(self.references)).batch
        self._plan, self._u, self._q_next = plan, batch.U[0], batch.Q_next[0]
        if fast:
            self._observe(q)
        elif rec is not None:
            rec.advance(state, self.dt, self.result)  # (the stack's advance: after the solve)
        self._k += 1

    def _observe(self, q: np.ndarray) -> None:
        """After a step of one kernel call (which advanced the stack): the recovery's watch,
        from the kernel's outcome (the watched tasks unmet, their references moving, their
        errors; :func:`~wholebody.kernels.watch.pose_watch`)."""
        rec = self.recovery
        if rec is None:
            return
        if self._bound is self._main:
            unmet, moving, error = pose_watch(*self._watch)
        else:  # the retreat's plan: the watched tasks are not in it
            unmet, moving, error = False, False, 0.0
        rec.observe(q, self.dt, unmet, moving, error)

    def _general(self, plan: Plan, q: np.ndarray, state: RobotState | None, j: int) -> RobotState:
        """A step with the Python entries' own code around the kernel call, and Pinocchio's
        kinematics for them (the stack has entries written in Python, a recovery watches, or
        the robot has joints the kernels do not move: then the kernel reads Pinocchio's
        kinematics too)."""
        if state is None:
            state = self.robot.update(q)
        for r, task in self._python_refs:
            task.set_target(self._refs[j, r, :16].reshape(4, 4), self._refs[j, r, 16:])  # type: ignore[index]
        plan.sync(state, self.dt)
        if plan.stale:  # an entry changed shape: laid out anew
            plan = self._rebind(state)
        self._plan_of_step = plan
        buffers = plan.step_buffers(len(self.references))
        what = INTEGRATE if self.recovery is not None else ADVANCE | INTEGRATE
        if buffers.movable:  # the kernel's kinematics, as in a step of one call
            self.solver.run(plan, buffers.own, buffers.batch, 1, what | KINEMATICS)
        else:
            self.solver.run(plan, buffers.pinocchio(), buffers.batch, 1, what)
        plan.evaluated = state.stamp
        if self.recovery is None:
            plan.advance_python(state, self.dt, buffers.batch.U[0])
        return state

    def _rebind(self, state: RobotState) -> Plan:
        """The stack laid out anew (an entry changed shape), references bound again."""
        stack = self.stack if self.recovery is None else self.recovery.stack
        plan = stack.synced_plan(state, self.dt)
        self._bind(plan)
        buffers = plan.step_buffers(len(self.references))
        buffers.batch.Q[0] = state.q
        if self.references:
            buffers.batch.refs[0] = self._refs[self._k % _BLOCK]  # type: ignore[index]
        return plan

    def _bind(self, plan: Plan) -> None:
        """The references of the compiled pose tasks of ``plan`` read by the kernel, the
        others set in Python; whether a step of ``plan`` is one kernel call."""
        self._python_refs = []
        for r, task in enumerate(self.references):
            if not plan.follow(task, r):
                self._python_refs.append((r, task))
        movable = plan.step_buffers(len(self.references)).movable
        self._fast = movable and not plan.python and not self._python_refs
        self._bound = plan
        self._call = None
        if self.recovery is not None and plan is self.stack.current_plan:
            names = {t.name for t in self.recovery.watched}
            rows = [k for k, n in enumerate(plan.task_names) if n in names]
            starts = [plan.block_start(t) for t in self.recovery.watched]
            self._watch = (
                plan.view(lay.F_PAR),
                np.array(starts, np.int64),
                plan.view(lay.I_INFEASIBLE),
                np.array(rows, np.int64),
            )
            self._fast = self._fast and min(starts) >= 0
            self._main = plan

    def _sample(self, k0: int) -> None:
        """Each reference's poses at steps ``k0 .. k0 + block - 1`` and its twists at the
        same steps (at mid-step with ``feedforward="midpoint"``), sampled in one vectorised
        call each, into the buffer the kernel reads (:data:`~wholebody.kernels.evaluate.
        REF_WIDTH` numbers a sample: the pose row by row, then the twist)."""
        if self._refs is None:
            self._refs = np.zeros((_BLOCK, len(self.references), REF_WIDTH))
        t = (k0 + np.arange(_BLOCK)) * self.dt
        t_ff = t + 0.5 * self.dt if self.feedforward == "midpoint" else t
        refs = self._refs
        for r, traj in enumerate(self.references.values()):
            s = traj.sample_many(np.concatenate((t, t_ff)))
            poses = refs[:, r, :16].reshape(_BLOCK, 4, 4)
            poses[:] = 0.0
            poses[:, :3, :3] = s.rotations[:_BLOCK]
            poses[:, :3, 3] = s.positions[:_BLOCK]
            poses[:, 3, 3] = 1.0
            refs[:, r, 16:19] = s.linear_velocities[_BLOCK:]
            refs[:, r, 19:22] = s.angular_velocities[_BLOCK:]

    # ------------------------------------------------------------------ a run
    def run(
        self,
        q0: np.ndarray,
        duration: float,
        *,
        progress: bool = False,
        callback: Callable[[int, float, np.ndarray], None] | None = None,
        phases: Mapping[str, tuple[float, float]] | None = None,
        meta: Mapping[str, object] | None = None,
        u0: np.ndarray | None = None,
    ) -> RunLog:
        """Run for ``duration`` seconds from ``q0``; ``callback(k, t, q)`` after each step
        (e.g. live visualisation). ``u0``: the velocity the robot has at the start (default: at
        rest), which constraints with a memory (acceleration limits) start from. Returns the
        :class:`RunLog`."""
        robot = self.robot
        q = robot.check_configuration(q0).copy()
        if not (isinstance(duration, numbers.Real) and math.isfinite(duration)):
            raise DimensionError(f"duration must be a finite number of seconds, got {duration!r}")
        n = round(duration / self.dt)
        if n < 1:
            raise DimensionError(f"duration {duration} s is shorter than one step of {self.dt} s")
        if self.latency and self.plant is None:
            raise WholebodyError(
                f"latency {self.latency}: a run without a plant integrates "
                "exactly, nothing is measured late (give the plant that is "
                "read late)"
            )
        tracked = [t for t in self.stack.tasks if isinstance(t, FrameTask)]
        log = _Recorder(
            robot,
            self.stack,
            self.monitors,
            tracked,
            n,
            float(getattr(self.solver, "tolerance", 1e-6)),
        )
        self.reset(u0)
        bar = progress_report(n, progress)
        with _threads(self.threads), _gc_paused():  # no collection mid-step
            q, done = self._loop(q, n, log, callback, bar)
        if bar is not None:
            bar.close()
        info = {
            "robot": robot.name,
            "dt": self.dt,
            "solver": getattr(self.solver, "name", type(self.solver).__name__),
            "levels": [[e.name for e in lv.entries] for lv in self.stack.levels],
            "actuated_joints": list(robot.actuated_joints),
            "groups": {g: grp.indices.tolist() for g, grp in robot.groups.items()},
            "position_limits": [lim.tolist() for lim in robot.position_limits],
            # which entries of each tracked frame task's error are its rotation (rad)
            "orientation_rows": {t.name: np.flatnonzero(t.rows >= 3).tolist() for t in tracked},
            "phases": {k: list(v) for k, v in (phases or {}).items()},
            "final_q": q.tolist(),
            **self._retreats(),
            **(meta or {}),
        }
        if done < n:
            info["stopped"] = self.plant.stop_reason  # type: ignore[union-attr]
        return log.finish(info, done)

    def _retreats(self) -> dict[str, list[list[float | None]]]:
        """``{"retreats": [[start, end], ...]}`` with a recovery, else nothing."""
        if self.recovery is None:
            return {}
        return {"retreats": [[r.start, r.end] for r in self.recovery.retreats]}

    def _loop(
        self,
        q: np.ndarray,
        n: int,
        log: _Recorder,
        callback: Callable[[int, float, np.ndarray], None] | None,
        bar: object,
    ) -> tuple[np.ndarray, int]:
        """The ``n`` control steps from ``q`` (fewer if the plant stops the run), each logged
        with the kinematics at its configuration. The final configuration and the steps
        done."""
        robot, latency = self.robot, self.latency
        measured = q  # the plant's configuration; q: the step's (advanced by the latency)
        for k in range(n):
            start = time.perf_counter()
            q = self._present(measured) if latency else measured
            predicted = time.perf_counter() - start
            state = robot.update(q)  # the log's kinematics (not the step's time)
            start = time.perf_counter()
            self._step(q, state)
            if latency:
                self._sent.append(self._u.copy())
            log.step_time[k] = time.perf_counter() - start + predicted
            t = k * self.dt
            plan = self._plan
            own = self.recovery is None or plan is self.stack.current_plan
            log.record(k, t, q, state, plan, self.solve_time, own)  # type: ignore[arg-type]
            if self.plant is None:
                measured = self.q_next.copy()
            else:  # a plant's step (a simulation) is not the controller's time
                measured = self.plant.step(measured, self._u.copy(), self.dt)
            if callback is not None:
                callback(k, t + self.dt, measured)
            if bar is not None:
                bar.update(1)  # type: ignore[attr-defined]
            if self.plant is not None and getattr(self.plant, "stop_reason", None):
                return measured, k + 1
        return measured, n


def _recovery(robot: Robot, stack: Stack, recovery: object) -> StallRecovery | None:
    """The controller's recovery from its ``recovery`` argument (see :class:`Controller`)."""
    if recovery is True:
        watched = any(isinstance(t, FrameTask) for t in stack.tasks)
        return StallRecovery(robot, stack) if watched else None
    if recovery is False or recovery is None:
        return None
    if not isinstance(recovery, StallRecovery):
        raise WholebodyError(f"recovery must be True, False or a StallRecovery, got {recovery!r}")
    if recovery.main is not stack:
        raise WholebodyError(
            "recovery must be made for the controller's stack: StallRecovery(robot, stack)"
        )
    return recovery


_BLOCK = 1024  # steps of reference sampled at once (memory: 176 bytes a step a reference)


def _thread_count(threads: object) -> int | None:
    """``threads`` checked: a whole number >= 1, or None."""
    if threads is None:
        return None
    if isinstance(threads, numbers.Integral) and not isinstance(threads, bool) and threads >= 1:
        return int(threads)
    raise WholebodyError(
        f"threads must be a whole number >= 1 (BLAS threads in the control "
        f"loop) or None (the libraries' own setting), got "
        f"{threads!r}"
    )


def _threads(count: int | None) -> contextlib.AbstractContextManager[object]:
    """The BLAS and OpenMP libraries limited to ``count`` threads (None: unchanged)."""
    return contextlib.nullcontext() if count is None else threadpool_limits(count)


@contextlib.contextmanager
def _gc_paused() -> Iterator[None]:
    """The cyclic garbage collector off while the loop runs, so that no collection lands
    inside a control step; restored after."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


class _Recorder:
    """Preallocated log arrays filled step by step."""

    def __init__(
        self,
        robot: Robot,
        stack: Stack,
        monitors: Sequence[ArmPotentialEnergy],
        tracked: list[FrameTask],
        n: int,
        tolerance: float = 1e-6,
    ) -> None:
        self.robot, self.monitors, self.tracked = robot, monitors, tracked
        self.stack = stack
        self.tolerance = tolerance  # the solver's: a task above it is unmet
        self.tasks: list[Task] = stack.tasks
        self.t = np.zeros(n)
        self.q = np.zeros((n, robot.nq))
        self.u = np.zeros((n, robot.nu))
        self.jp = np.zeros((n, robot.nu))
        self.step_time = np.zeros(n)
        self.solve_time = np.zeros(n)
        self.status = np.zeros(n, dtype=np.int8)
        self.limit_hit = np.zeros(n, dtype=bool)
        self.failed = np.zeros(n, dtype=bool)
        self.causes = {t.name: np.zeros(n, dtype=np.int8) for t in self.tasks}
        self.level_res = np.zeros((n, len(stack.levels)))
        self.errors = {t.name: np.zeros((n, t.dim)) for t in self.tasks}
        self.pos = {t.name: np.zeros((n, 3)) for t in tracked}
        self.ref = {t.name: np.zeros((n, 3)) for t in tracked}
        self.energies = [m for m in monitors if isinstance(m, ArmPotentialEnergy)]
        self.others = [m for m in monitors if not isinstance(m, ArmPotentialEnergy)]
        self.arms = {m.arm.name: np.zeros((n, 6)) for m in self.energies}
        self.values = {m.name: np.zeros(n) for m in self.others}

    def record(
        self,
        k: int,
        t: float,
        q: np.ndarray,
        state: RobotState,
        plan: Plan,
        solve_time: float,
        own: bool = True,
    ) -> None:
        """Step ``k``'s row from the solve's outcome in ``plan``'s arena; ``own``: solved with
        the controller's stack (else a retreat's, whose level residuals are not the stack's:
        NaN)."""
        out, U, levels = plan.view(lay.I_OUT), plan.view(lay.F_U), plan.view(lay.F_LEVEL_OUT)
        status = int(out[lay.OUT_STATUS])
        self.t[k] = t
        self.q[k] = q
        self.u[k] = U[1]
        self.jp[k] = state.joint_positions()
        self.solve_time[k] = solve_time
        self.status[k] = status
        self.limit_hit[k] = (
            status in (SolverStatus.BOUNDS_ACTIVE, SolverStatus.SCALED)
            or plan.view(lay.I_ACTIVE).any()
            or (levels[:, 1] < 1.0).any()
        )
        causes, self.failed[k] = classify(plan, self.tolerance)
        if causes.any():
            for name, cause in zip(plan.task_names, causes.tolist(), strict=True):
                if cause and name in self.causes:
                    self.causes[name][k] = cause
        self.level_res[k] = levels[:, 0] if own else np.nan
        for task in self.tasks:
            self.errors[task.name][k] = task.error(state)
        for task in self.tracked:
            self.pos[task.name][k] = state.position(task.frame)
            self.ref[task.name][k] = task.target[:3, 3] if task.target is not None else np.nan
        for m in self.energies:  # the solve's own value when the stack has the same energy
            parts = plan.arm_parts(m, state)
            self.arms[m.arm.name][k] = parts if parts is not None else m.parts(state)
        for m in self.others:
            self.values[m.name][k] = m.evaluate(state).value

    def finish(self, meta: dict, n: int) -> RunLog:
        """The log of the first ``n`` steps."""
        return RunLog(
            t=self.t[:n],
            q=self.q[:n],
            u=self.u[:n],
            joint_positions=self.jp[:n],
            step_time=self.step_time[:n],
            solve_time=self.solve_time[:n],
            status=self.status[:n],
            limit_hit=self.limit_hit[:n],
            level_residuals=self.level_res[:n],
            task_errors={k: v[:n] for k, v in self.errors.items()},
            frame_positions={k: v[:n] for k, v in self.pos.items()},
            reference_positions={k: v[:n] for k, v in self.ref.items()},
            arms={a: ArmTrace(*v[:n].T.copy()) for a, v in self.arms.items()},
            objectives={k: v[:n] for k, v in self.values.items()},
            meta=meta,
            failed=self.failed[:n],
            unmet={k: v[:n] for k, v in self.causes.items()},
        )


def progress_report(
    n: int,
    enabled: bool,
    desc: str = "control",
    *,
    leave: bool = False,
    every: float = 10.0,
    stream: IO[str] | None = None,
) -> Any:
    """A progress report over ``n`` steps, or None when not ``enabled``.

    On a terminal (``stream``, default stderr, is a TTY): a tqdm bar. Elsewhere (a log file,
    a pipe, CI, a notebook) no bar, because tqdm redraws its bar with carriage returns that
    a log keeps as one ever-growing line: a plain line at most every ``every`` seconds (s)
    and one when it closes. Either has ``update(k)``, ``set_postfix_str(text)`` and
    ``close()``. ``leave``: the bar stays on the terminal once closed."""
    if not enabled:
        return None
    import sys

    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    if isatty is not None and isatty():
        from tqdm import tqdm

        return tqdm(total=n, unit="step", desc=desc, leave=leave, file=stream)

    class _Lines:
        """Plain progress lines: ``desc: k/n steps (p %), t s, postfix``."""

        def __init__(self) -> None:
            self.k, self.postfix = 0, ""
            self.start = self.last = time.perf_counter()

        def _line(self, text: str) -> None:
            print(f"{desc}: {text}", file=stream, flush=True)

        def update(self, k: int = 1) -> None:
            self.k += k
            now = time.perf_counter()
            if now - self.last >= every and self.k < n:
                self.last = now
                extra = f", {self.postfix}" if self.postfix else ""
                self._line(
                    f"{self.k}/{n} steps ({100 * self.k / n:.0f} %), "
                    f"{now - self.start:.0f} s{extra}"
                )

        def set_postfix_str(self, text: str) -> None:
            self.postfix = text

        def close(self) -> None:
            self._line(f"{self.k}/{n} steps in {time.perf_counter() - self.start:.1f} s")

    return _Lines()
