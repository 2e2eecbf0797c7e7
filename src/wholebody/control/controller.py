"""The control loop: references -> tasks -> solver -> integrate -> log.

One step at time ``t_k = k dt``:

1. every referenced task gets its target: the reference pose at ``t_k`` and, as the
   paper's feed-forward ``x'_d``, the reference twist at the **mid-step** ``t_k + dt/2``.
   With ``u`` held for the step, the mid-step twist makes the commanded motion the secant
   of the reference to second order, so the tracking error does not lag by ``a dt / 2 Kp``
   as with the twist at ``t_k`` (set ``feedforward="start"`` for the latter);
2. kinematics at ``q_k`` (:meth:`Robot.update`), the solver's ``u_k``;
3. the log row (errors, tracked positions against references, arm energies);
4. the tasks' integrators advance, each with its own anti-windup (its integral stops
   growing while a bound limits that task: :meth:`Stack.saturated_tasks
   <wholebody.solvers.Stack.saturated_tasks>`; a joint no task moves may rest on its limit);
5. ``q_{k+1} = integrate(q_k, u_k, dt)`` (exact on the configuration manifold), or with a
   ``plant`` the configuration it reaches under ``u_k`` (a physics simulation).

``step_time`` is the wall time of the control computation of a step: targets (reference
sampling), kinematics, stack evaluation, solve, the integrators' advance and the integration,
without the log's own recording and monitoring (and without a plant's simulation).
"""

from __future__ import annotations

import contextlib
import gc
import math
import numbers
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Protocol, runtime_checkable

import numpy as np
from threadpoolctl import threadpool_limits

from wholebody.control.log import ArmTrace, RunLog
from wholebody.control.recovery import StallRecovery
from wholebody.errors import DimensionError, WholebodyError
from wholebody.planning.trajectory import Trajectory
from wholebody.robot import Robot
from wholebody.solvers.base import Solver
from wholebody.solvers.result import SolverStatus
from wholebody.solvers.stack import Stack
from wholebody.tasks.arm_energy import ArmPotentialEnergy
from wholebody.tasks.base import Objective, Task
from wholebody.tasks.frame import FrameTask

__all__ = ["Controller", "Plant", "ReferenceTask"]


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
        A :class:`~wholebody.control.recovery.StallRecovery` for ``stack`` (default none):
        retreat to a ready posture when the tasks stall in a local minimum, then retry. The
        run log's ``meta["retreats"]`` lists them (``[start, end]`` in s; end None if the run
        ended during one).
    plant
        What the commands drive (default: the exact integration :meth:`Robot.integrate`):
        an object with ``step(q, u, dt) -> q`` returning the configuration reached, such as
        :class:`wholebody.sim.MujocoPlant` (physics), whose configuration the controller then
        reads. A plant whose ``stop_reason`` becomes a string ends the run after that step
        (the log holds the steps done; ``meta["stopped"]`` the reason).
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
        recovery: StallRecovery | None = None,
        plant: Plant | None = None,
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
                raise WholebodyError(f"monitors are objectives (ArmPotentialEnergy, "
                                     f"JointLimitAvoidance, ...), got {m!r}")  # fmt: skip
        self.feedforward = feedforward
        if recovery is not None and recovery.main is not stack:
            raise WholebodyError("recovery must be made for the controller's stack: "
                                 "StallRecovery(robot, stack)")  # fmt: skip
        self.recovery = recovery
        if plant is not None and not callable(getattr(plant, "step", None)):
            raise WholebodyError(f"plant must have step(q, u, dt) -> q (e.g. "
                                 f"wholebody.sim.MujocoPlant), got {plant!r}")  # fmt: skip
        self.plant = plant
        self.threads = _thread_count(threads)

    def _sampled_targets(self, k0: int, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each reference's poses at steps ``k0 .. k0+n-1`` and its twists at the same steps
        (at mid-step with ``feedforward="midpoint"``), sampled in one vectorised call."""
        t = (k0 + np.arange(n)) * self.dt
        t_ff = t + 0.5 * self.dt if self.feedforward == "midpoint" else t
        out = []
        for traj in self.references.values():
            s = traj.sample_many(np.concatenate((t, t_ff)))
            poses = np.zeros((n, 4, 4))
            poses[:, :3, :3] = s.rotations[:n]
            poses[:, :3, 3] = s.positions[:n]
            poses[:, 3, 3] = 1.0
            out.append((poses, np.hstack((s.linear_velocities[n:], s.angular_velocities[n:]))))
        return out

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
        tracked = [t for t in self.stack.tasks if isinstance(t, FrameTask)]
        log = _Recorder(robot, self.stack, self.monitors, tracked, n)
        self.stack.reset()
        if self.recovery is not None:
            self.recovery.reset()
        if u0 is not None:
            u0 = np.asarray(u0, dtype=float)
            if u0.shape != (robot.nu,) or not np.isfinite(u0).all():
                raise DimensionError(f"u0 must be {robot.nu} finite velocities, got {u0!r}")
            self.stack.set_velocity(u0, self.dt)
        bar = _progress(n, progress)
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
        """The ``n`` control steps from ``q`` (fewer if the plant stops the run); the
        references sampled a block at a time. The final configuration and the steps done."""
        robot, tasks, rec = self.robot, list(self.references), self.recovery
        advance = robot.integrate if self.plant is None else self.plant.step
        for k in range(n):
            start = time.perf_counter()  # the step's time includes its share of the sampling
            if k % _BLOCK == 0:
                targets = self._sampled_targets(k, min(_BLOCK, n - k))
            t, j = k * self.dt, k % _BLOCK
            for task, (poses, twists) in zip(tasks, targets, strict=True):
                task.set_target(poses[j], twists[j])
            state = robot.update(q)
            stack = self.stack if rec is None else rec.stack
            result = self.solver.solve(stack, state, self.dt)
            compute = time.perf_counter() - start
            log.record(k, t, q, state, result, stack is self.stack)  # before the next update
            start = time.perf_counter()
            if rec is None:
                stack.advance(state, self.dt, result=result)
            else:
                rec.advance(state, self.dt, result)
            if self.plant is None:  # the integration is the controller's own work
                q = advance(q, result.u, self.dt)
                log.step_time[k] = compute + (time.perf_counter() - start)
            else:  # a plant's step (a simulation) is not the controller's time
                log.step_time[k] = compute + (time.perf_counter() - start)
                q = advance(q, result.u, self.dt)
            if callback is not None:
                callback(k, t + self.dt, q)
            if bar is not None:
                bar.update(1)  # type: ignore[attr-defined]
            if self.plant is not None and getattr(self.plant, "stop_reason", None):
                return q, k + 1
        return q, n


_BLOCK = 1024  # steps of reference sampled at once (memory: 176 bytes a step a reference)


def _thread_count(threads: object) -> int | None:
    """``threads`` checked: a whole number >= 1, or None."""
    if threads is None:
        return None
    if isinstance(threads, numbers.Integral) and not isinstance(threads, bool) and threads >= 1:
        return int(threads)
    raise WholebodyError(f"threads must be a whole number >= 1 (BLAS threads in the control "
                         f"loop) or None (the libraries' own setting), got "
                         f"{threads!r}")  # fmt: skip


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
    ) -> None:
        self.robot, self.monitors, self.tracked = robot, monitors, tracked
        self.stack = stack
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
        self.top = stack.levels[0].name
        self.level_res = np.zeros((n, len(stack.levels)))
        self.errors = {t.name: np.zeros((n, t.dim)) for t in self.tasks}
        self.pos = {t.name: np.zeros((n, 3)) for t in tracked}
        self.ref = {t.name: np.zeros((n, 3)) for t in tracked}
        self.energies = [m for m in monitors if isinstance(m, ArmPotentialEnergy)]
        self.others = [m for m in monitors if not isinstance(m, ArmPotentialEnergy)]
        self.arms = {m.arm.name: np.zeros((n, 6)) for m in self.energies}
        self.values = {m.name: np.zeros(n) for m in self.others}

    def record(self, k: int, t: float, q: np.ndarray, state, result, own: bool = True) -> None:
        """Step ``k``'s row; ``own``: solved with the controller's stack (else a retreat's,
        whose level residuals are not the stack's: NaN)."""
        self.t[k] = t
        self.q[k] = q
        self.u[k] = result.u
        self.jp[k] = state.joint_positions()
        self.solve_time[k] = result.solve_time
        self.status[k] = int(result.status)
        self.limit_hit[k] = result.limit_hit
        self.failed[k] = result.status == SolverStatus.FAILED or any(
            level == self.top for level, _ in result.infeasible
        )
        self.level_res[k] = result.level_residuals if own else np.nan
        for task in self.tasks:
            self.errors[task.name][k] = task.error(state)
        for task in self.tracked:
            self.pos[task.name][k] = state.position(task.frame)
            self.ref[task.name][k] = task.target[:3, 3] if task.target is not None else np.nan
        plan = self.stack.current_plan
        for m in self.energies:  # the solve's own value when the stack has the same energy
            parts = plan.arm_parts(m, state) if plan is not None else None
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
        )


def _progress(
    n: int,
    enabled: bool,
    desc: str = "control",
    *,
    leave: bool = False,
    every: float = 10.0,
    stream=None,
):
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
                self._line(f"{self.k}/{n} steps ({100 * self.k / n:.0f} %), "
                           f"{now - self.start:.0f} s{extra}")  # fmt: skip

        def set_postfix_str(self, text: str) -> None:
            self.postfix = text

        def close(self) -> None:
            self._line(f"{self.k}/{n} steps in {time.perf_counter() - self.start:.1f} s")

    return _Lines()
