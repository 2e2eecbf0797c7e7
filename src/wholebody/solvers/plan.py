"""A stack compiled for the kernels: its layout, made once, and the per-step synchronisation.

At the first compiled solve a :class:`~wholebody.solvers.stack.Stack` builds a :class:`Plan`:
every number the kernels read or write goes into the regions of two flat arenas
(:mod:`wholebody.kernels.layout`), and the constant ones (frames, supports, row layout,
limits, networks) are written there once. Each step, :meth:`Plan.sync` copies into the arena
what may have changed since the last step (a new target, a new gain or weight, the
integrals are shared in place) and lets every entry written in Python (a user's task,
objective or constraint, or a built-in one the kernels do not know) write its rows, gradient
or box into it; one kernel call (:func:`wholebody.kernels.evaluate.evaluate`, or a solver's,
which starts with it) then does the rest.

Built-in entries are compiled when their type is exactly the built-in class (a subclass may
override a method): :class:`~wholebody.tasks.FrameTask`,
:class:`~wholebody.tasks.RelativeFrameTask`, :class:`~wholebody.tasks.PostureTask`,
:class:`~wholebody.tasks.FrameHalfSpace`, :class:`~wholebody.tasks.ArmPotentialEnergy` with a
constant or network stiffness, :class:`~wholebody.tasks.JointLimitAvoidance`,
:class:`~wholebody.tasks.Manipulability`, :class:`~wholebody.tasks.JointPositionLimits` and
:class:`~wholebody.tasks.VelocityLimits`. Everything else takes the Python path: slower,
never wrong.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from wholebody import kernels
from wholebody.arm.stiffness import ConstantStiffness
from wholebody.errors import DimensionError
from wholebody.kernels import layout as lay
from wholebody.kernels.evaluate import evaluate
from wholebody.kernels.objectives import AE_CONSTANT, AE_K, AE_NET, AE_WIDTH, ARM_PARTS
from wholebody.robot import Frame, RobotState
from wholebody.robot.hessian import actuated_support_mask
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.tasks.arm_energy import ArmEnergyValue, ArmPotentialEnergy
from wholebody.tasks.base import Constraint, InequalityTask, Objective, ObjectiveValue, Task
from wholebody.tasks.frame import FrameTask
from wholebody.tasks.inequality import FrameHalfSpace
from wholebody.tasks.limits import JointPositionLimits, VelocityLimits
from wholebody.tasks.objectives import JointLimitAvoidance, Manipulability
from wholebody.tasks.posture import PostureTask
from wholebody.tasks.relative import RelativeFrameTask

if TYPE_CHECKING:
    from wholebody.solvers.stack import Level, LevelProblem, Stack, StackProblem

__all__ = ["Arena", "Plan", "ProblemArena", "is_compiled", "sqrt_weights"]

_POSE_TYPES = (FrameTask, RelativeFrameTask)
_WARM = {"evaluate": False}  # whether a kernel entry point ran in this process


def sqrt_weights(task: Task, w: object) -> np.ndarray:
    """``sqrt(w)`` per row of ``task`` for the weight(s) ``w`` (a number or one per row,
    finite and >= 0), or :class:`DimensionError`."""
    try:
        wa = np.broadcast_to(np.asarray(w, dtype=float), (task.dim,))
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{task.name}: weight must be a number or {task.dim} numbers, "
                             f"got {w!r}") from exc  # fmt: skip
    if not (np.all(np.isfinite(wa)) and np.all(wa >= 0)):
        raise DimensionError(f"{task.name}: weights must be finite and >= 0, got {w!r}")
    return np.sqrt(wa)


def first_call(name: str, what: str, call: Callable[..., Any], *args: Any) -> Any:
    """``call(*args)``, telling the user when its first call in this process compiles."""
    if _WARM.get(name):
        return call(*args)
    with kernels.compile_notice(what):
        out = call(*args)
    _WARM[name] = True
    return out


class _Rows:
    """An equality task's rows ``[start, stop)`` and the weight they were scaled with."""

    __slots__ = ("key", "level", "start", "stop", "task")

    def __init__(self, task: Task, level: int, start: int) -> None:
        self.task, self.level, self.start, self.stop = task, level, start, start + task.dim
        self.key: object = None


class _Pose:
    """A compiled pose task's row of ``F_POSE``: what was copied there last."""

    __slots__ = ("error", "integral", "ki", "kp", "par", "target", "task", "twist")

    def __init__(self, task: FrameTask | RelativeFrameTask, par: np.ndarray) -> None:
        self.task, self.par = task, par
        self.target = self.twist = self.kp = self.ki = None
        self.integral = par[lay.POSE_INTEGRAL : lay.POSE_INTEGRAL + 6]
        self.error = par[lay.POSE_ERROR : lay.POSE_ERROR + 6]

    def sync(self, state: RobotState) -> None:
        t, par = self.task, self.par
        target = t.current_target(state)
        if target is not self.target:
            par[lay.POSE_TARGET : lay.POSE_TARGET + 16] = target.ravel()
            self.target = target
        if t._twist is not self.twist:
            self.twist = par[lay.POSE_TWIST : lay.POSE_TWIST + 6] = t._twist
        if t._kp is not self.kp:
            self.kp = par[lay.POSE_KP : lay.POSE_KP + 6] = t._kp
        if t._ki is not self.ki:
            self.ki = par[lay.POSE_KI : lay.POSE_KI + 6] = t._ki
        if t.integral is not self.integral:  # share it: advance() updates it in place
            self.integral[:] = t.integral
            t.integral = self.integral
        if t._error is not self.error:
            t._error = self.error

    def written(self, state: RobotState) -> None:
        self.task._error_key = (state, self.target)


class _Posture:
    """A compiled posture task's entries of ``F_POSTURE``."""

    __slots__ = ("kp", "par", "target", "task")

    def __init__(self, task: PostureTask, par: np.ndarray) -> None:
        self.task, self.par = task, par
        self.target = self.kp = None

    def sync(self) -> None:
        t = self.task
        if t._target is not self.target:
            self.target = self.par[0] = t._target
        if t._kp is not self.kp:
            self.kp = self.par[1] = t._kp


class _Arm:
    """A compiled arm energy's row of ``F_ARM``: the settings it was written from."""

    __slots__ = ("objective", "par", "settings", "stiffness")

    def __init__(self, objective: ArmPotentialEnergy, par: np.ndarray) -> None:
        self.objective, self.par = objective, par
        self.settings = (objective.smoothing, objective.fade, objective.reference, objective.g)
        self.stiffness = objective.stiffness

    def sync(self) -> bool:
        """Copy what changed; False when the stiffness is no longer the one laid out."""
        o = self.objective
        if o.stiffness is not self.stiffness:
            return False
        settings = (o.smoothing, o.fade, o.reference, o.g)
        if settings != self.settings:
            net, k = self.par[AE_NET], self.par[AE_K]
            self.par[:] = o.parameters()
            self.par[AE_NET], self.par[AE_K] = net, k
            self.settings = settings
        if self.par[AE_NET] == AE_CONSTANT:
            self.par[AE_K] = o.stiffness.k
        return True


def _compiled_objective(o: Objective) -> bool:
    if type(o) is ArmPotentialEnergy:  # (links beyond one per segment: evaluated in Python)
        return not o.extra_bodies and (
            type(o.stiffness) is ConstantStiffness or o.network() is not None
        )
    return type(o) in (JointLimitAvoidance, Manipulability)


class Arena:
    """Numbers laid out for the kernels: the float and int arenas and the header of their
    regions (:mod:`wholebody.kernels.layout`), with numpy views of the regions and the
    reading of a solver kernel's outcome."""

    def __init__(self, shapes: dict[int, tuple[int, ...]]) -> None:
        full = dict.fromkeys(range(lay.N_REGIONS), (0,))
        full.update(shapes)
        self.f, self.i, self.h = lay.build(full)
        self._shapes_of = full
        self._outputs: tuple[np.ndarray, ...] | None = None
        self.reported: list[tuple[int, str, str]] = []
        """``(task index, task name, level name)`` of the equality tasks a result reports."""
        self.inequality_rows: list[tuple[int, int, int, str]] = []
        """``(level, first row, last row, name)`` of the inequality tasks."""
        self.level_names: list[str] = []
        self.task_names: list[str] = []
        """The equality tasks' names, in the order of ``I_TASK``."""

    def view(self, region: int) -> np.ndarray:
        """Region ``region`` of the arenas as a numpy view (written by the kernels too)."""
        arena = self.f if region < lay.N_FLOAT else self.i
        return lay.view(arena, self.h, region, self._shapes_of[region])

    def result(self, solve_time: float, message: str = "", scale: bool = True) -> SolverResult:
        """The solver kernel's outcome in the arena as a :class:`SolverResult` (``scale``:
        report the per-level scale factors, else ones)."""
        if self._outputs is None:
            v = self.view
            self._outputs = (v(lay.I_OUT), v(lay.F_U), v(lay.F_LEVEL_OUT), v(lay.F_TASK_RES),
                             v(lay.I_INFEASIBLE), v(lay.I_ACTIVE))  # fmt: skip
        out, U, lev, res, infeasible, active = self._outputs
        flags = infeasible.tolist()
        plain = res[:, 1].tolist()
        reported = self.reported
        return SolverResult(
            u=U[1].copy(),
            status=SolverStatus(int(out[lay.OUT_STATUS])),
            level_residuals=lev[:, 0].copy(),
            task_residuals={name: plain[t] for t, name, _ in reported},
            active_bounds=np.flatnonzero(active),
            scale=lev[:, 1].copy() if scale else np.ones(lev.shape[0]),
            infeasible=[(level, name) for t, name, level in reported if flags[t]],
            solve_time=solve_time,
            message=message,
        )


class ProblemArena(Arena):
    """An evaluated :class:`~wholebody.solvers.stack.StackProblem` (rows in scaled
    coordinates) laid out for the solver kernels alone: how the compiled solvers take a
    problem that no stack made (tests, fuzzing)."""

    def __init__(self, problem: StackProblem) -> None:
        from wholebody.solvers.stack import OBJECTIVES

        levels = problem.levels
        n = problem.lower.shape[0]
        K = sum(lp.A.shape[0] for lp in levels)
        P = sum(lp.C.shape[0] for lp in levels)
        tasks = []  # (level, start, stop, name)
        k = 0
        for li, lp in enumerate(levels):
            rows = sorted((sl.start, sl.stop, name) for name, sl in lp.task_rows.items()
                          if name != OBJECTIVES and sl.stop > sl.start)  # fmt: skip
            tasks += [(li, k + a, k + z, name) for a, z, name in rows]
            k += lp.A.shape[0]
        L = len(levels)
        super().__init__({
            lay.F_METRIC: (2, n), lay.F_ROW: (2, K), lay.F_LEVEL: (L, 4), lay.F_A: (K, n),
            lay.F_B: (K,), lay.F_C: (P, n), lay.F_CB: (2, P), lay.F_BOX: (2, n),
            lay.F_U: (2, n), lay.F_LEVEL_OUT: (L, 2), lay.F_TASK_RES: (len(tasks), 3),
            lay.I_LEVEL: (L, lay.LEVEL_INTS), lay.I_TASK: (len(tasks), 3),
            lay.I_OUT: (lay.OUT_INTS,), lay.I_ACTIVE: (n,), lay.I_INFEASIBLE: (len(tasks),),
            lay.I_INEQ: (sum(len(lp.inequality_rows) for lp in levels), 3),
        })  # fmt: skip
        v = self.view
        metric = v(lay.F_METRIC)
        metric[0] = problem.scale
        metric[1] = problem.scale**2
        box = v(lay.F_BOX)
        box[0], box[1] = problem.lower, problem.upper
        A, b, C, CB = v(lay.F_A), v(lay.F_B), v(lay.F_C), v(lay.F_CB)
        rw, lf, li_ = v(lay.F_ROW), v(lay.F_LEVEL), v(lay.I_LEVEL)
        k = p = 0
        for j, lp in enumerate(levels):
            m, c = lp.A.shape[0], lp.C.shape[0]
            A[k : k + m], b[k : k + m] = lp.A, lp.b
            rw[1, k : k + m] = 1.0 if lp.unweight is None else lp.unweight
            C[p : p + c], CB[0, p : p + c], CB[1, p : p + c] = lp.C, lp.lower, lp.upper
            lf[j, lay.LEVEL_IDENTITY] = lp.identity_scale
            lf[j, lay.LEVEL_REFERENCE] = lp.reference_scale
            li_[j] = (k, k + m, k + m, p, p + c, 1)
            k, p = k + m, p + c
        if tasks:
            v(lay.I_TASK)[:] = [t[:3] for t in tasks]
        self.reported = [(t, name, levels[li].name) for t, (li, _, _, name) in enumerate(tasks)]
        self.task_names = [name for *_, name in tasks]
        self.level_names = [lp.name for lp in levels]
        k = 0
        for li, lp in enumerate(levels):
            for name, sl in sorted(lp.inequality_rows.items(), key=lambda kv: kv[1].start):
                self.inequality_rows.append((li, k + sl.start, k + sl.stop, name))
            k += lp.C.shape[0]
        if self.inequality_rows:
            v(lay.I_INEQ)[:] = [row[:3] for row in self.inequality_rows]


class Plan(Arena):
    """The compiled layout of one stack (see the module docstring). Built by the stack."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        self.robot = stack.robot
        self.levels: list[Level] = list(stack.levels)
        self.entries = [lv.entries for lv in self.levels]
        self._frames: dict[int, int] = {}  # frame index -> its row in the frames table
        self._frame_list: list[Frame] = []
        self._collect()
        super().__init__(self._shapes())
        self.inequality_rows = self._inequality_rows
        self._fill_constants()
        self.reported = [(t, r.task.name, self.levels[r.level].name)
                         for t, r in enumerate(self.rows) if r.stop > r.start]  # fmt: skip
        self.task_names = [r.task.name for r in self.rows]
        self.level_names = [lv.name for lv in self.levels]
        self._problem: StackProblem | None = None
        self.metric_version = -1
        self.stale = False
        self.evaluated: RobotState | None = None  # the state of the last kernel evaluation

    # ------------------------------------------------------------------ layout
    def _frame(self, frame: Frame) -> int:
        k = self._frames.get(frame.index)
        if k is None:
            k = self._frames[frame.index] = len(self._frame_list)
            self._frame_list.append(frame)
        return k

    def _collect(self) -> None:
        """Sort the entries into the tables and lay out the rows of every level."""
        nu = self.robot.nu
        self.rows: list[_Rows] = []  # every equality task, in order
        self.pose_tasks, self.posture_tasks, self.python_tasks = [], [], []
        self.half_spaces, self.python_inequalities = [], []
        self._inequality_rows: list[tuple[int, int, int, str]] = []  # level, rows, name
        self.objectives: list[tuple[Objective, int]] = []  # (objective, level)
        self.level_rows: list[tuple[int, int, int, int, int]] = []
        k = p = 0
        for li, level in enumerate(self.levels):
            row0 = k
            for t in level.tasks:
                self.rows.append(_Rows(t, li, k))
                if type(t) in _POSE_TYPES:
                    self.pose_tasks.append(len(self.rows) - 1)
                elif type(t) is PostureTask:
                    self.posture_tasks.append(len(self.rows) - 1)
                else:
                    self.python_tasks.append(len(self.rows) - 1)
                k += t.dim
            tasks_end = k
            if level.objectives:
                k += nu
                self.objectives += [(o, li) for o in level.objectives]
            ineq0 = p
            for t in level.inequalities:
                kind = self.half_spaces if type(t) is FrameHalfSpace else self.python_inequalities
                kind.append((t, p))
                self._inequality_rows.append((li, p, p + t.dim, t.name))
                p += t.dim
            self.level_rows.append((row0, tasks_end, k, ineq0, p))
        self.K, self.P = k, p
        for r in self.pose_tasks:
            t = self.rows[r].task
            if type(t) is RelativeFrameTask:
                self._frame(t.frame_a)
            self._frame(t.frame_b if type(t) is RelativeFrameTask else t.frame)
        for t, _ in self.half_spaces:
            self._frame(t.frame)
        self.arms = [o for o, _ in self.objectives
                     if type(o) is ArmPotentialEnergy and _compiled_objective(o)]  # fmt: skip
        self.h1 = [o for o, _ in self.objectives if type(o) is JointLimitAvoidance]
        self.h2 = [o for o, _ in self.objectives if type(o) is Manipulability]
        for o in self.arms:
            for fr in o._frames_base if o.network() is not None else o._frames:
                self._frame(fr)
        for o in self.h2:
            for fr in o.frames:
                self._frame(fr)
        self.python_objectives = [j for j, (o, _) in enumerate(self.objectives)
                                  if not _compiled_objective(o)]  # fmt: skip
        cons = self.stack.constraints
        self.pos_limits = [c for c in cons if type(c) is JointPositionLimits]
        self.vel_limits = [c for c in cons if type(c) is VelocityLimits]
        builtin = (JointPositionLimits, VelocityLimits)
        self.python_constraints = [c for c in cons if type(c) not in builtin]

    def _shapes(self) -> dict[int, tuple[int, ...]]:
        robot = self.robot
        nu, nv, F = robot.nu, robot.nv, len(self._frame_list)
        E = robot.kinematics.act_k.size
        nE = sum(self.rows[r].task.dim for r in self.posture_tasks)
        nets = sum(o.network().size for o in self.arms if o.network() is not None)
        fmax = max((len(o.frames) for o in self.h2), default=0)
        L, T, nO = len(self.levels), len(self.rows), len(self.objectives)
        return {
            lay.F_SCALARS: (4,), lay.F_ACT_A: (E,), lay.F_KIN_J: (F, 6, nu),
            lay.F_KIN_P: (F, 3), lay.F_KIN_R: (F, 3, 3), lay.F_JP: (nu,),
            lay.F_POSE: (len(self.pose_tasks), lay.POSE_WIDTH), lay.F_POSTURE: (3, nE),
            lay.F_HALF: (len(self.half_spaces), 5), lay.F_ARM: (len(self.arms), AE_WIDTH),
            lay.F_ARM_PARTS: (len(self.arms), ARM_PARTS), lay.F_NETS: (max(nets, 1),),
            lay.F_H1: (len(self.h1), 3, nu), lay.F_OBJ: (nO, 2), lay.F_OBJ_GRAD: (nO, nu),
            lay.F_OBJ_CURV: (nO, nu), lay.F_POS_BOX: (len(self.pos_limits), 3, nu),
            lay.F_VEL_BOX: (len(self.vel_limits), nu),
            lay.F_PY_BOX: (len(self.python_constraints), 2, nu), lay.F_METRIC: (2, nu),
            lay.F_ROW: (2, self.K), lay.F_LEVEL: (L, 4), lay.F_A: (self.K, nu),
            lay.F_B: (self.K,), lay.F_C: (self.P, nu), lay.F_CB: (2, self.P),
            lay.F_BOX: (2, nu), lay.F_U: (2, nu), lay.F_LEVEL_OUT: (L, 2), lay.F_TASK_RES: (T, 3),
            lay.I_FRAME: (F,), lay.I_SUPPORT: (F, nv), lay.I_ACT: (2, E), lay.I_POS: (2, nu),
            lay.I_POSE: (len(self.pose_tasks), lay.POSE_INTS),
            lay.I_POSTURE: (len(self.posture_tasks), 3), lay.I_POSTURE_ENTRY: (3, nE),
            lay.I_HALF: (len(self.half_spaces), 2), lay.I_ARM: (len(self.arms), 6),
            lay.I_H2: (len(self.h2), 1 + fmax), lay.I_H2_MASK: (nu, nu) if self.h2 else (0, 0),
            lay.I_OBJ: (nO, 4), lay.I_LEVEL: (L, lay.LEVEL_INTS), lay.I_TASK: (T, 3),
            lay.I_BOX: (3,), lay.I_OUT: (lay.OUT_INTS,), lay.I_ACTIVE: (nu,),
            lay.I_INFEASIBLE: (T,), lay.I_INEQ: (len(self._inequality_rows), 3),
        }  # fmt: skip

    def _fill_constants(self) -> None:
        robot, kin, v = self.robot, self.robot.kinematics, self.view
        frames = self._frame_list
        v(lay.I_FRAME)[:] = [fr.index for fr in frames]
        v(lay.I_SUPPORT)[:] = kin.support(frames)
        v(lay.I_ACT)[:] = (kin.act_k, kin.act_j)
        v(lay.F_ACT_A)[:] = kin.act_a
        v(lay.I_POS)[:] = (kin.position_index, kin.position_pair)
        self._fill_tasks()
        self._fill_objectives()
        levels = v(lay.I_LEVEL)
        for li, (row0, tasks_end, row_end, ineq0, ineq_end) in enumerate(self.level_rows):
            levels[li] = (row0, tasks_end, row_end, ineq0, ineq_end,
                          bool(self.levels[li].tasks))  # fmt: skip
        v(lay.I_TASK)[:] = [(r.level, r.start, r.stop) for r in self.rows] or np.zeros((0, 3))
        v(lay.I_INEQ)[:] = [row[:3] for row in self._inequality_rows] or np.zeros((0, 3))
        for j, c in enumerate(self.pos_limits):
            v(lay.F_POS_BOX)[j] = (*c.limits, np.full(robot.nu, c.gain))
        for j, c in enumerate(self.vel_limits):
            v(lay.F_VEL_BOX)[j] = c.upper
        v(lay.I_BOX)[:] = (len(self.pos_limits), len(self.vel_limits), len(self.python_constraints))
        v(lay.F_LEVEL)[:, lay.LEVEL_REFERENCE] = 1.0
        self._Fpose = v(lay.F_POSE)
        self._A, self._b = v(lay.F_A), v(lay.F_B)
        self._C, self._CB = v(lay.F_C), v(lay.F_CB)
        self._row_weights = v(lay.F_ROW)
        self._level_f = v(lay.F_LEVEL)
        self._obj = v(lay.F_OBJ)
        self._scalars = v(lay.F_SCALARS)

    def _fill_tasks(self) -> None:
        v = self.view
        ints, par = v(lay.I_POSE), v(lay.F_POSE)
        self._pose: list[_Pose] = []
        for k, r in enumerate(self.pose_tasks):
            rows, t = self.rows[r], self.rows[r].task
            if type(t) is RelativeFrameTask:
                fa, fb = self._frames[t.frame_a.index], self._frames[t.frame_b.index]
            else:
                fa, fb = -1, self._frames[t.frame.index]
            ints[k, : lay.POSE_SEL] = (fa, fb, rows.start, t.dim)
            ints[k, lay.POSE_SEL : lay.POSE_SEL + t.dim] = t.rows
            self._pose.append(_Pose(t, par[k]))
        tasks, entries, ppar = v(lay.I_POSTURE), v(lay.I_POSTURE_ENTRY), v(lay.F_POSTURE)
        self._posture: list[_Posture] = []
        e = 0
        for k, r in enumerate(self.posture_tasks):
            t = self.rows[r].task
            n = t.dim
            tasks[k] = (self.rows[r].start, e, n)
            entries[:, e : e + n] = (t.indices, t.tracked, t.wrapped)
            self._posture.append(_Posture(t, ppar[:2, e : e + n]))
            e += n
        ints, par = v(lay.I_HALF), v(lay.F_HALF)
        for k, (t, row) in enumerate(self.half_spaces):
            ints[k] = (self._frames[t.frame.index], row)
            par[k] = (*t.normal, t.offset, t.gain)

    def _fill_objectives(self) -> None:
        v = self.view
        table = v(lay.I_OBJ)
        arm_ints, arm_par, nets = v(lay.I_ARM), v(lay.F_ARM), v(lay.F_NETS)
        self._arms: list[_Arm] = []
        offset = 0
        for k, o in enumerate(self.arms):
            frames = o._frames_base if o.network() is not None else o._frames
            arm_ints[k] = [self._frames[fr.index] for fr in frames] + [-1] * (6 - len(frames))
            arm_par[k] = o.parameters()
            network = o.network()
            if network is None:
                arm_par[k, AE_NET] = AE_CONSTANT
            else:
                nets[offset : offset + network.size] = network
                arm_par[k, AE_NET] = offset
                offset += network.size
            self._arms.append(_Arm(o, arm_par[k]))
        for k, o in enumerate(self.h1):
            v(lay.F_H1)[k] = o.ranges
        h2 = v(lay.I_H2)
        for k, o in enumerate(self.h2):
            frames = [self._frames[fr.index] for fr in o.frames]
            h2[k, : 1 + len(frames)] = [len(frames), *frames]
        if self.h2:
            v(lay.I_H2_MASK)[:] = actuated_support_mask(self.robot)
        kinds = {ArmPotentialEnergy: (lay.KIND_ARM, self.arms), JointLimitAvoidance:
                 (lay.KIND_H1, self.h1), Manipulability: (lay.KIND_H2, self.h2)}  # fmt: skip
        for j, (o, level) in enumerate(self.objectives):
            kind, members = kinds.get(type(o), (lay.KIND_PYTHON, ()))
            if kind != lay.KIND_PYTHON and o not in members:
                kind = lay.KIND_PYTHON  # an arm energy with a stiffness evaluated in Python
            index = next(i for i, m in enumerate(members) if m is o) if kind else j
            table[j] = (kind, index, level, kind == lay.KIND_H1)

    # ------------------------------------------------------------------ each step
    def sync(self, state: RobotState, dt: float) -> None:
        """Copy into the arena what changed since the last step and let the Python entries
        write their rows, gradients and boxes (unscaled); sets :attr:`stale` when the stack
        must be laid out anew (an arm energy's stiffness was replaced)."""
        stack = self.stack
        self._scalars[0] = dt
        if stack._scale_version != self.metric_version:
            metric = self.view(lay.F_METRIC)
            metric[0], metric[1] = stack.scale, stack._scale_sq
            self.metric_version = stack._scale_version
        lf = self._level_f
        for li, level in enumerate(self.levels):
            lf[li, lay.LEVEL_GAIN] = level.gain
            lf[li, lay.LEVEL_OBJECTIVE_WEIGHT] = level.objective_weight
        for pose in self._pose:
            pose.sync(state)
        for posture in self._posture:
            posture.sync()
        A, b = self._A, self._b
        for r in self.python_tasks:
            rows = self.rows[r]
            w = rows.task.write_rows(state, A[rows.start : rows.stop], b[rows.start : rows.stop])
            self._weigh(rows, w)
        for r in self.pose_tasks:
            self._weigh(self.rows[r], self.rows[r].task.weight)
        for r in self.posture_tasks:
            self._weigh(self.rows[r], self.rows[r].task.weight)
        self._sync_objectives(state)
        self._sync_python_boxes(state, dt)

    def _weigh(self, rows: _Rows, w: object) -> None:
        """The rows' weight (a number or one per row): rescale them where it changed."""
        key = rows.key
        if isinstance(w, (float, int)):
            if key.__class__ is float and w == key:
                return
        elif key.__class__ is np.ndarray and np.array_equal(w, key):
            return
        sw = sqrt_weights(rows.task, w)
        rows.key = float(w) if isinstance(w, (float, int)) else np.array(w, float)
        rw = self._row_weights
        rw[0, rows.start : rows.stop] = sw
        rw[1, rows.start : rows.stop] = np.divide(1.0, sw, out=np.zeros_like(sw), where=sw > 0)
        row0, tasks_end = self.level_rows[rows.level][:2]
        weighted = rw[0, row0:tasks_end]
        weighted = weighted[weighted > 0.0]
        self._level_f[rows.level, lay.LEVEL_REFERENCE] = (
            float(weighted.min()) if weighted.size else 1.0
        )

    def _sync_objectives(self, state: RobotState) -> None:
        obj = self._obj
        for j, (o, _) in enumerate(self.objectives):
            obj[j, 0] = o.weight
        for arm in self._arms:
            if not arm.sync():
                self.stale = True
        if self.python_objectives:
            grads, curvs = self.view(lay.F_OBJ_GRAD), self.view(lay.F_OBJ_CURV)
            table = self.view(lay.I_OBJ)
            self._python_values: dict[str, ObjectiveValue] = {}
            for j in self.python_objectives:
                o = self.objectives[j][0]
                val = o.evaluate(state)
                self._python_values[o.name] = val
                grads[j] = val.gradient
                if val.curvature is not None:
                    curvs[j] = val.curvature
                table[j, lay.OBJ_HAS_CURV] = val.curvature is not None
                obj[j, 1] = val.value

    def _sync_python_boxes(self, state: RobotState, dt: float) -> None:
        if self.python_constraints:
            boxes = self.view(lay.F_PY_BOX)
            for j, c in enumerate(self.python_constraints):
                bounds = c.bounds(state, dt)
                boxes[j, 0], boxes[j, 1] = bounds.lower, bounds.upper
        C, CB = self._C, self._CB
        for t, row in self.python_inequalities:
            r = t.compute(state, dt)
            C[row : row + t.dim] = r.C
            CB[0, row : row + t.dim] = r.lower
            CB[1, row : row + t.dim] = r.upper

    def kernel_args(self, state: RobotState) -> tuple[np.ndarray, ...]:
        """``(f, i, h, J, oMf, q)``: what every kernel entry point takes."""
        J, oMf = self.robot.kinematics.views()
        return self.f, self.i, self.h, J, oMf, state.q

    def written(self, state: RobotState) -> None:
        """After a kernel evaluated the rows at ``state``: the pose tasks' errors are theirs."""
        for pose in self._pose:
            pose.written(state)
        self.evaluated = state

    def evaluate(self, state: RobotState, dt: float) -> None:
        """Sync and evaluate every row and the box at ``state`` (scaled, in the arena)."""
        self.sync(state, dt)
        first_call("evaluate", "the control kernels", evaluate, *self.kernel_args(state))
        self.written(state)

    # ------------------------------------------------------------------ the evaluated problem
    def problem(self) -> StackProblem:
        """The arena's rows as a :class:`~wholebody.solvers.stack.StackProblem` of views
        (overwritten by the next evaluation), for the reference solvers and for users."""
        from wholebody.solvers.stack import LevelProblem, StackProblem

        if self._problem is None:
            levels: list[LevelProblem] = []
            rw = self._row_weights
            for li, (level, (row0, _, row_end, ineq0, ineq_end)) in enumerate(
                zip(self.levels, self.level_rows, strict=True)
            ):
                rows = {r.task.name: slice(r.start - row0, r.stop - row0)
                        for r in self.rows if r.level == li}  # fmt: skip
                if level.objectives:
                    rows["objectives"] = slice(self.level_rows[li][1] - row0, row_end - row0)
                irows, p = {}, 0
                for t in level.inequalities:
                    irows[t.name] = slice(p, p + t.dim)
                    p += t.dim
                levels.append(LevelProblem(level.name, self._A[row0:row_end],
                                           self._b[row0:row_end], self._C[ineq0:ineq_end],
                                           self._CB[0, ineq0:ineq_end],
                                           self._CB[1, ineq0:ineq_end], rows, irows,
                                           unweight=rw[1, row0:row_end]))  # fmt: skip
            box = self.view(lay.F_BOX)
            self._problem = StackProblem(levels, box[0], box[1], self.stack.scale, {})
        problem = self._problem
        problem.scale = self.stack.scale
        lf = self._level_f
        for li, lp in enumerate(problem.levels):
            lp.identity_scale = float(lf[li, lay.LEVEL_IDENTITY])
            lp.reference_scale = float(lf[li, lay.LEVEL_REFERENCE])
        return problem

    def objective_values(self) -> dict[str, ObjectiveValue]:
        """Every objective's value, gradient and curvature at the last evaluation."""
        out: dict[str, ObjectiveValue] = {}
        grads, curvs = self.view(lay.F_OBJ_GRAD), self.view(lay.F_OBJ_CURV)
        table = self.view(lay.I_OBJ)
        parts = self.view(lay.F_ARM_PARTS)
        for j, (o, _) in enumerate(self.objectives):
            kind, k, _, has_curv = table[j].tolist()
            if kind == lay.KIND_PYTHON:
                out[o.name] = self._python_values[o.name]
            elif kind == lay.KIND_ARM:
                value, gravity, spring, alpha, stiff, rho = parts[k].tolist()
                out[o.name] = ArmEnergyValue(value, grads[j].copy(), None, gravity, spring,
                                             alpha, stiff, rho)  # fmt: skip
            else:
                curv = curvs[j].copy() if has_curv else None
                out[o.name] = ObjectiveValue(float(self._obj[j, 1]), grads[j].copy(), curv)
        return out

    def arm_parts(self, energy: ArmPotentialEnergy, state: RobotState) -> np.ndarray | None:
        """``energy``'s parts (:meth:`ArmPotentialEnergy.parts`) as the last kernel evaluation
        computed them for an arm energy of the stack with the same value, if that evaluation
        was at ``state``; else None."""
        if state is not self.evaluated:
            return None
        for k, arm in enumerate(self.arms):
            if arm.same_energy(energy):
                return self.view(lay.F_ARM_PARTS)[k]
        return None


def is_compiled(entry: Task | InequalityTask | Objective | Constraint) -> bool:
    """Whether the kernels compute ``entry`` themselves (else it runs in Python)."""
    if isinstance(entry, Objective):
        return _compiled_objective(entry)
    return type(entry) in (*_POSE_TYPES, PostureTask, FrameHalfSpace, JointPositionLimits,
                           VelocityLimits)  # fmt: skip
