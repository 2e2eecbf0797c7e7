"""A stack compiled for the kernels: its layout, made once, and the per-step synchronisation.

At the first compiled solve a :class:`~wholebody.solvers.stack.Stack` builds a :class:`Plan`:
every number the kernels read or write goes into the regions of two flat arenas
(:mod:`wholebody.kernels.layout`). Each entry of the stack (task, inequality task, objective,
limit) is one row of the entry table: its level, rows, slot, and what it packed itself into
(:meth:`wholebody.tasks.Task.pack`: its kernel and its parameter block, which the plan copies
into the arena and the entry adopts, so both share one memory from then on). The plan never
looks at an entry's type or private attributes.

Each step, :meth:`Plan.sync` writes what Python owns: ``dt``, the metric, the levels' gains and
the weights where they changed, the blocks of entries that another stack adopted in between,
and the rows, gradients, inequality rows and boxes of the entries written in Python (a
user's, or a built-in one whose subclass overrides what it computes). One kernel call does the
rest.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from wholebody import kernels
from wholebody.errors import DimensionError, ModelError
from wholebody.kernels import control
from wholebody.kernels import layout as lay
from wholebody.kernels.evaluate import REF_WIDTH, evaluate
from wholebody.kernels.objectives import AE_WIDTH, ARM_PARTS
from wholebody.robot import Frame, Robot, RobotState
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.tasks.arm_energy import ArmEnergyValue, ArmPotentialEnergy
from wholebody.tasks.base import (
    InequalityTask,
    Limit,
    Objective,
    ObjectiveValue,
    Packed,
    Packer,
    Task,
)

if TYPE_CHECKING:
    from wholebody.solvers.stack import LevelProblem, Stack, StackProblem

__all__ = [
    "Arena",
    "BoundCall",
    "Plan",
    "ProblemArena",
    "is_compiled",
    "kinematics_buffers",
    "sqrt_weights",
]

Entry = Task | InequalityTask | Objective | Limit
_WARM: dict[str, bool] = {}  # whether a kernel entry point ran in this process
NO_REFERENCES = np.zeros((0, REF_WIDTH))
_PARAMS = operator.attrgetter("_params")
LEVEL_SETTINGS = [0]  # how many times a level's gain or objective weight was set (any level)


def sqrt_weights(task: Task, w: object) -> np.ndarray:
    """``sqrt(w)`` per row of ``task`` for the weight(s) ``w`` (a number or one per row,
    finite and >= 0), or :class:`DimensionError`."""
    try:
        wa = np.broadcast_to(np.asarray(w, dtype=float), (task.dim,))
    except (TypeError, ValueError) as exc:
        raise DimensionError(
            f"{task.name}: weight must be a number or {task.dim} numbers, got {w!r}"
        ) from exc
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


class BoundCall:
    """``call(*args)`` with its arguments bound: a call without arguments, as a controller
    makes every period.

    numba's dispatcher finds the type of every argument at each call, in Python for a record
    of arrays (a namedtuple): about 0.8 us for one of six arrays, 2.4 us for the three of a
    control step. The bound arguments are the same objects at every call (a plan's buffers,
    a solver's settings vector), so their types are too: after the first call (through the
    dispatcher, compiling if needed), the compiled entry point of their signature is called
    directly, the same machine code without the typing."""

    def __init__(self, name: str, what: str, call: Callable[..., Any], *args: Any) -> None:
        self.args = args
        self.bound = False  # whether the entry point is called directly
        self._next: Callable[[], Any] = functools.partial(self._first, name, what, call)

    def __call__(self) -> Any:
        return self._next()

    def _first(self, name: str, what: str, call: Callable[..., Any]) -> Any:
        out = first_call(name, what, call, *self.args)
        overloads = getattr(call, "overloads", None)
        found = None
        if overloads is not None and not kernels.DISABLED:
            found = overloads.get(tuple(call.typeof_pyval(a) for a in self.args))
        self.bound = found is not None
        self._next = functools.partial(found.entry_point if found else call, *self.args)
        return out


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
        self.workspaces: dict[str, Any] = {}
        """A solver's own buffers for these arenas, by solver (the HQP's cascade state)."""
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
            self._outputs = (
                v(lay.I_OUT),
                v(lay.F_U),
                v(lay.F_LEVEL_OUT),
                v(lay.F_TASK_RES),
                v(lay.I_INFEASIBLE),
                v(lay.I_ACTIVE),
            )
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
            source=self,
        )

    def write_result(self, result: SolverResult) -> None:
        """A result (of another solve, or changed by its user) into the outcome regions, for
        what reads them after a solve (the anti-windup of :meth:`Plan.advance`)."""
        v = self.view
        D = v(lay.F_METRIC)[0]
        U = v(lay.F_U)
        U[1] = result.u
        U[0] = result.u / D
        active = v(lay.I_ACTIVE)
        active[:] = 0
        active[np.asarray(result.active_bounds, dtype=np.intp)] = 1
        scale = np.asarray(result.scale, dtype=float)
        levels = v(lay.F_LEVEL_OUT)
        levels[:, 1] = scale if scale.size == levels.shape[0] else 1.0
        unmet = {name for _, name in result.infeasible}
        v(lay.I_INFEASIBLE)[:] = [name in unmet for name in self.task_names]


class ProblemArena(Arena):
    """An evaluated :class:`~wholebody.solvers.stack.StackProblem` (rows in scaled
    coordinates) laid out for the solver kernels alone: how the compiled solvers take a
    problem that no stack made (tests, fuzzing, the torque level's problem). :meth:`fill`
    writes the numbers of another problem of the same layout into it."""

    def __init__(self, problem: StackProblem) -> None:
        from wholebody.solvers.stack import OBJECTIVES

        levels = problem.levels
        n = problem.lower.shape[0]
        K = sum(lp.A.shape[0] for lp in levels)
        P = sum(lp.C.shape[0] for lp in levels)
        tasks = []  # (level, start, stop, name)
        k = 0
        for li, lp in enumerate(levels):
            rows = sorted(
                (sl.start, sl.stop, name)
                for name, sl in lp.task_rows.items()
                if name != OBJECTIVES and sl.stop > sl.start
            )
            tasks += [(li, k + a, k + z, name) for a, z, name in rows]
            k += lp.A.shape[0]
        L = len(levels)
        super().__init__(
            {
                lay.F_METRIC: (2, n),
                lay.F_ROW: (2, K),
                lay.F_LEVEL: (L, 4),
                lay.F_A: (K, n),
                lay.F_B: (K,),
                lay.F_C: (P, n),
                lay.F_CB: (2, P),
                lay.F_BOX: (4, n),
                lay.F_ANCHOR: (n,),
                lay.F_U: (2, n),
                lay.F_LEVEL_OUT: (L, 2),
                lay.F_TASK_RES: (len(tasks), 3),
                lay.I_LEVEL: (L, lay.LEVEL_INTS),
                lay.I_TASK: (len(tasks), 3),
                lay.I_OUT: (lay.OUT_INTS,),
                lay.I_ACTIVE: (n,),
                lay.I_INFEASIBLE: (len(tasks),),
                lay.I_SATURATED: (len(tasks),),
                lay.I_INEQ: (sum(len(lp.inequality_rows) for lp in levels), 3),
                lay.I_HELD: (P,),
                lay.I_UNMET0: (len(tasks),),
            }
        )
        v = self.view
        li_ = v(lay.I_LEVEL)
        k = p = 0
        for j, lp in enumerate(levels):
            m, c = lp.A.shape[0], lp.C.shape[0]
            li_[j] = (k, k + m, k + m, p, p + c, 1)
            k, p = k + m, p + c
        self.fill(problem)
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

    def fill(self, problem: StackProblem) -> None:
        """The numbers of ``problem`` (the same levels, rows and variables as the problem
        the arena was laid out for; its levels need only the attributes ``A``, ``b``, ``C``,
        ``lower``, ``upper``, ``unweight``, ``identity_scale`` and ``reference_scale``)."""
        v = self.view
        metric = v(lay.F_METRIC)
        metric[0] = problem.scale
        metric[1] = problem.scale**2
        box = v(lay.F_BOX)
        box[0], box[1] = problem.lower, problem.upper
        box[2], box[3] = problem.lower, problem.upper  # (no separate velocity box known)
        if problem.anchor is not None:
            v(lay.F_ANCHOR)[:] = problem.anchor
        A, b, C, CB = v(lay.F_A), v(lay.F_B), v(lay.F_C), v(lay.F_CB)
        rw, lf = v(lay.F_ROW), v(lay.F_LEVEL)
        k = p = 0
        for j, lp in enumerate(problem.levels):
            m, c = lp.A.shape[0], lp.C.shape[0]
            A[k : k + m], b[k : k + m] = lp.A, lp.b
            rw[1, k : k + m] = 1.0 if lp.unweight is None else lp.unweight
            C[p : p + c], CB[0, p : p + c], CB[1, p : p + c] = lp.C, lp.lower, lp.upper
            lf[j, lay.LEVEL_IDENTITY] = lp.identity_scale
            lf[j, lay.LEVEL_REFERENCE] = lp.reference_scale
            k, p = k + m, p + c


class _Record:
    """An entry of the plan: where it lies, what it packed, and (Python entries) what its
    rows were last weighted with."""

    __slots__ = ("block", "cat", "entry", "key", "level", "packed", "row", "rows", "slot")

    def __init__(self, entry: Entry, cat: int, level: int, row: int, rows: int, slot: int) -> None:
        self.entry, self.cat, self.level = entry, cat, level
        self.row, self.rows, self.slot = row, rows, slot
        self.packed = None
        self.block: np.ndarray | None = None
        self.key: object = None


class Plan(Arena):
    """The compiled layout of one stack (see the module docstring). Built by the stack."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        self.robot = stack.robot
        self.levels = list(stack.levels)
        self.entries = [lv.entries for lv in self.levels]
        self.constraints = list(stack.constraints)
        self._frames: dict[int, int] = {}  # frame index -> its row in the frame table
        self._frame_list: list[Frame] = []
        self._collect()
        super().__init__(self._shapes())
        self.inequality_rows = self._inequality_rows
        self._fill()
        self._compiled_entries = [r.entry for r in self.compiled]
        self._blocks = [r.block for r in self.compiled]  # (an entry's block while it is ours)
        self._dt: float | None = None  # the step the entries were checked for
        self._gains = -1  # LEVEL_SETTINGS when the levels' numbers were written
        self.reported = [
            (t, r.entry.name, self.levels[r.level].name) for t, r in enumerate(self.tasks) if r.rows
        ]
        self.task_names = [r.entry.name for r in self.tasks]
        self.level_names = [lv.name for lv in self.levels]
        self._problem: StackProblem | None = None
        self._python_values: dict[str, ObjectiveValue] = {}
        self.metric_version = -1
        self._steps: StepBuffers | None = None
        self.stale = False
        self.evaluated = -1.0  # the stamp of the state of the last kernel evaluation
        self.last_result: SolverResult | None = None
        """The result a solver made of this plan's last solve (its outcome is in the arena)."""

    # ------------------------------------------------------------------ layout
    def frame(self, frame: Frame) -> int:
        """The row of ``frame`` in the frame table (:class:`~wholebody.tasks.base.Packer`)."""
        k = self._frames.get(frame.index)
        if k is None:
            k = self._frames[frame.index] = len(self._frame_list)
            self._frame_list.append(frame)
        return k

    def _collect(self) -> None:
        """One record per entry, rows and slots assigned, and what each entry packed."""
        nu = self.robot.nu
        self.records: list[_Record] = []
        self.tasks: list[_Record] = []
        self.objectives: list[_Record] = []
        self.level_rows: list[tuple[int, int, int, int, int]] = []
        self._inequality_rows: list[tuple[int, int, int, str]] = []
        k = p = 0
        for li, level in enumerate(self.levels):
            row0 = k
            for t in level.tasks:
                self.tasks.append(self._add(t, lay.CAT_TASK, li, k, t.dim, len(self.tasks)))
                k += t.dim
            tasks_end = k
            if level.objectives:
                k += nu
            ineq0 = p
            for t in level.inequalities:
                self._add(t, lay.CAT_INEQUALITY, li, p, t.dim, -1)
                self._inequality_rows.append((li, p, p + t.dim, t.name))
                p += t.dim
            for o in level.objectives:
                self.objectives.append(
                    self._add(o, lay.CAT_OBJECTIVE, li, 0, 0, len(self.objectives))
                )
            self.level_rows.append((row0, tasks_end, k, ineq0, p))
        for j, c in enumerate(self.constraints):
            self._add(c, lay.CAT_LIMIT, -1, 0, 0, j)
        self.K, self.P = k, p
        for rec in self.records:
            rec.packed = _pack(rec.entry, self)
        self.compiled = [r for r in self.records if r.packed is not None]
        self.python = [r for r in self.records if r.packed is None]

    def _add(self, entry: Entry, cat: int, level: int, row: int, rows: int, slot: int) -> _Record:
        rec = _Record(entry, cat, level, row, rows, slot)
        self.records.append(rec)
        return rec

    def _shapes(self) -> dict[int, tuple[int, ...]]:
        robot = self.robot
        nu, nv, F = robot.nu, robot.nv, len(self._frame_list)
        E = robot.kinematics.act_k.size
        L, T, nO = len(self.levels), len(self.tasks), len(self.objectives)
        nF = sum(r.packed.floats.size for r in self.compiled)
        nI = sum(r.packed.ints.size for r in self.compiled)
        return {
            lay.F_SCALARS: (4,),
            lay.F_ACT_A: (E,),
            lay.F_KIN_J: (F, 6, nu),
            lay.F_KIN_P: (F, 3),
            lay.F_KIN_R: (F, 3, 3),
            lay.F_JP: (nu,),
            lay.F_PAR: (nF,),
            lay.F_OBJ: (nO, 2),
            lay.F_OBJ_GRAD: (nO, nu),
            lay.F_OBJ_CURV: (nO, nu),
            lay.F_BOXES: (len(self.constraints), 2, nu),
            lay.F_METRIC: (2, nu),
            lay.F_ROW: (2, self.K),
            lay.F_LEVEL: (L, 4),
            lay.F_A: (self.K, nu),
            lay.F_B: (self.K,),
            lay.F_C: (self.P, nu),
            lay.F_CB: (2, self.P),
            lay.F_BOX: (4, nu),
            lay.F_ANCHOR: (nu,),
            lay.F_U: (2, nu),
            lay.F_LEVEL_OUT: (L, 2),
            lay.F_TASK_RES: (T, 3),
            lay.I_FRAME: (F,),
            lay.I_SUPPORT: (F, nv),
            lay.I_ACT: (2, E),
            lay.I_POS: (2, nu),
            lay.I_ENTRY: (len(self.records), lay.ENTRY_INTS),
            lay.I_PAR: (nI,),
            lay.I_LEVEL: (L, lay.LEVEL_INTS),
            lay.I_TASK: (T, 3),
            lay.I_OUT: (lay.OUT_INTS,),
            lay.I_ACTIVE: (nu,),
            lay.I_INFEASIBLE: (T,),
            lay.I_SATURATED: (T,),
            lay.I_INEQ: (len(self._inequality_rows), 3),
            lay.I_HELD: (self.P,),
            lay.I_UNMET0: (T,),
        }

    def _fill(self) -> None:
        """The constants: frames, kinematics tables, the entry table, levels, tasks; every
        compiled entry's block copied in and adopted."""
        kin, v = self.robot.kinematics, self.view
        frames = self._frame_list
        v(lay.I_FRAME)[:] = [fr.index for fr in frames]
        v(lay.I_SUPPORT)[:] = kin.support(frames)
        v(lay.I_ACT)[:] = (kin.act_k, kin.act_j)
        v(lay.F_ACT_A)[:] = kin.act_a
        v(lay.I_POS)[:] = (kin.position_index, kin.position_pair)
        table, fpar, ipar = v(lay.I_ENTRY), v(lay.F_PAR), v(lay.I_PAR)
        f0 = i0 = 0
        for e, rec in enumerate(self.records):
            row = table[e]
            row[:] = (
                rec.cat,
                lay.KIND_PYTHON,
                rec.level,
                rec.row,
                rec.rows,
                rec.slot,
                -1,
                0,
                0,
                0,
                0,
                0,
            )
            packed = rec.packed
            if packed is None:
                continue
            nf, ni = packed.floats.size, packed.ints.size
            row[lay.E_KIND], row[lay.E_FLAG] = packed.kind, packed.curvature
            row[lay.E_F0], row[lay.E_FN], row[lay.E_I0], row[lay.E_IN] = f0, nf, i0, ni
            rec.block = fpar[f0 : f0 + nf]
            rec.block[:] = packed.floats
            ipar[i0 : i0 + ni] = packed.ints
            rec.entry.adopt(rec.block)
            f0, i0 = f0 + nf, i0 + ni
        levels = v(lay.I_LEVEL)
        for li, (row0, tasks_end, row_end, ineq0, ineq_end) in enumerate(self.level_rows):
            levels[li] = (row0, tasks_end, row_end, ineq0, ineq_end, bool(self.levels[li].tasks))
        v(lay.I_TASK)[:] = [(r.level, r.row, r.row + r.rows) for r in self.tasks] or np.zeros(
            (0, 3)
        )
        v(lay.I_INEQ)[:] = [row[:3] for row in self._inequality_rows] or np.zeros((0, 3))
        v(lay.F_LEVEL)[:, lay.LEVEL_REFERENCE] = 1.0
        self._table = table
        self._A, self._b = v(lay.F_A), v(lay.F_B)
        self._C, self._CB = v(lay.F_C), v(lay.F_CB)
        self._row_weights = v(lay.F_ROW)
        self._level_f = v(lay.F_LEVEL)
        self._obj = v(lay.F_OBJ)
        self._boxes = v(lay.F_BOXES)
        self._scalars = v(lay.F_SCALARS)

    def _compiled(self, entry: object) -> int:
        """The row of ``entry`` in the entry table if it is a compiled entry of the stack,
        else -1."""
        for e, rec in enumerate(self.records):
            if rec.entry is entry and rec.packed is not None:
                return e
        return -1

    def follow(self, task: object, reference: int) -> bool:
        """Let ``task``, if it is a compiled pose task of the stack, take its target and
        twist from row ``reference`` of the references' samples each step (-1: no longer);
        whether it is one."""
        e = self._compiled(task)
        if e < 0 or self.records[e].packed.kind != lay.KIND_POSE:  # type: ignore[union-attr]
            return False
        self._table[e, lay.E_REF] = reference
        return True

    def block_start(self, entry: object) -> int:
        """Where the parameter block of ``entry``, a compiled entry of the stack, starts in
        the arena's ``F_PAR`` (-1 if it is not one)."""
        e = self._compiled(entry)
        return -1 if e < 0 else int(self._table[e, lay.E_F0])

    # ------------------------------------------------------------------ each step
    def sync(self, state: RobotState | None, dt: float) -> None:
        """Write into the arena what Python owns (see the module docstring); sets
        :attr:`stale` when the stack must be laid out anew (an entry's block changed
        shape). ``state``: the kinematics at the step's configuration (None where the kernel
        computes them: then every entry must be compiled)."""
        stack = self.stack
        scalars = self._scalars
        if dt != self._dt:
            for rec in self.records:
                rec.entry.check_step(dt)
            scalars[0] = self._dt = dt
        scalars[2] = -1.0 if state is None else state.stamp
        if stack._scale_version != self.metric_version:
            metric = self.view(lay.F_METRIC)
            metric[0], metric[1] = stack.scale, stack._scale_sq
            self.metric_version = stack._scale_version
        if LEVEL_SETTINGS[0] != self._gains:
            gains = [(level.gain, level.objective_weight) for level in self.levels]
            self._level_f[:, lay.LEVEL_GAIN : lay.LEVEL_OBJECTIVE_WEIGHT + 1] = gains
            self._gains = LEVEL_SETTINGS[0]
        if not all(map(operator.is_, map(_PARAMS, self._compiled_entries), self._blocks)):
            for rec in self.compiled:
                if rec.entry._params is not rec.block:
                    self._readopt(rec)
        for rec in self.tasks:
            if rec.packed is not None and rec.entry.weight is not rec.key:
                self._weigh(rec, rec.entry.weight)
            if rec.packed is not None and rec.entry.lm_damping:  # damped from now on: in Python
                self.stale = True
        obj = self._obj
        for rec in self.objectives:
            obj[rec.slot, 0] = rec.entry.weight
        if self.python:
            if state is None:
                raise DimensionError("entries written in Python need the robot's state")
            self._sync_python(state, dt)

    def _readopt(self, rec: _Record) -> None:
        """An entry whose block is no longer the plan's (another stack adopted it, or it
        made a new one): copy it back in, or lay the stack out anew if it changed shape."""
        params = rec.entry._params
        packed = rec.entry.pack(_Probe(self._frames))
        if (
            packed is None
            or packed.kind != rec.packed.kind
            or params.size != rec.block.size
            or not np.array_equal(packed.ints, rec.packed.ints)
        ):
            self.stale = True
            return
        rec.block[:] = params
        rec.entry.adopt(rec.block)

    def _weigh(self, rec: _Record, w: object) -> None:
        """The rows' weight (a number or one per row): rescale them where it changed."""
        key = rec.key
        if isinstance(w, (float, int)):
            if key.__class__ is float and w == key:
                rec.key = w
                return
        elif key.__class__ is np.ndarray and np.array_equal(w, key):
            rec.key = w
            return
        sw = sqrt_weights(rec.entry, w)
        rec.key = (
            w
            if rec.packed is not None
            else (float(w) if isinstance(w, (float, int)) else np.array(w, float))
        )
        rw = self._row_weights
        rw[0, rec.row : rec.row + rec.rows] = sw
        rw[1, rec.row : rec.row + rec.rows] = np.divide(
            1.0, sw, out=np.zeros_like(sw), where=sw > 0
        )
        row0, tasks_end = self.level_rows[rec.level][:2]
        weighted = rw[0, row0:tasks_end]
        weighted = weighted[weighted > 0.0]
        self._level_f[rec.level, lay.LEVEL_REFERENCE] = (
            float(weighted.min()) if weighted.size else 1.0
        )

    def _sync_python(self, state: RobotState, dt: float) -> None:
        """The rows, gradients, inequality rows and boxes of the entries written in Python
        (unscaled: the kernel scales them)."""
        A, b, C, CB = self._A, self._b, self._C, self._CB
        grads, curvs = self.view(lay.F_OBJ_GRAD), self.view(lay.F_OBJ_CURV)
        table = self._table
        self._python_values = {}
        for e, rec in enumerate(self.records):
            if rec.packed is not None:
                continue
            entry, r0, r1 = rec.entry, rec.row, rec.row + rec.rows
            if rec.cat == lay.CAT_TASK:
                w = entry.write_rows(state, A[r0:r1], b[r0:r1])
                if entry.lm_damping:
                    entry.damp(state, A[r0:r1], b[r0:r1], w)
                self._weigh(rec, w)
            elif rec.cat == lay.CAT_INEQUALITY:
                rows = entry.compute(state, dt)
                C[r0:r1], CB[0, r0:r1], CB[1, r0:r1] = rows.C, rows.lower, rows.upper
            elif rec.cat == lay.CAT_OBJECTIVE:
                val = entry.evaluate(state)
                self._python_values[entry.name] = val
                grads[rec.slot] = val.gradient
                if val.curvature is not None:
                    curvs[rec.slot] = val.curvature
                table[e, lay.E_FLAG] = val.curvature is not None
                self._obj[rec.slot, 1] = val.value
            else:
                box = entry.bounds(state, dt)
                self._boxes[rec.slot, 0], self._boxes[rec.slot, 1] = box.lower, box.upper

    def kernel_args(self, state: RobotState) -> tuple[np.ndarray, ...]:
        """``(f, i, h, J, oMf, q)``: what every kernel entry point takes first."""
        J, oMf = self.robot.kinematics.views()
        return self.f, self.i, self.h, J, oMf, state.q

    def step_buffers(self, references: int = 0) -> StepBuffers:
        """The buffers of a compiled step with ``references`` references (made once)."""
        steps = self._steps
        if steps is None or steps.references != references:
            steps = self._steps = StepBuffers(self, references)
        return steps

    def evaluate(self, state: RobotState, dt: float) -> None:
        """Sync and evaluate every row and the box at ``state`` (scaled, in the arena)."""
        self.sync(state, dt)
        first_call(
            "evaluate", "the control kernels", evaluate, *self.kernel_args(state), NO_REFERENCES
        )
        self.evaluated = state.stamp

    # ------------------------------------------------------------------ after a solve
    def advance_python(self, state: RobotState, dt: float, u: np.ndarray | None) -> None:
        """The Python entries' own step: tasks' integrators with the anti-windup flags the
        kernel computed, limits' memories (when ``u`` is given)."""
        flags = self.view(lay.I_SATURATED)
        for rec in self.python:
            if rec.cat == lay.CAT_TASK:
                rec.entry.advance(state, dt, bool(flags[rec.slot]))
            elif rec.cat == lay.CAT_LIMIT and u is not None:
                rec.entry.advance(u, dt)

    # ------------------------------------------------------------------ the evaluated problem
    def problem(self) -> StackProblem:
        """The arena's rows as a :class:`~wholebody.solvers.stack.StackProblem` of views
        (overwritten by the next evaluation), for users and tests."""
        from wholebody.solvers.stack import OBJECTIVES, LevelProblem, StackProblem

        if self._problem is None:
            levels: list[LevelProblem] = []
            rw = self._row_weights
            for li, (level, (row0, tasks_end, row_end, ineq0, ineq_end)) in enumerate(
                zip(self.levels, self.level_rows, strict=True)
            ):
                rows = {
                    r.entry.name: slice(r.row - row0, r.row + r.rows - row0)
                    for r in self.tasks
                    if r.level == li
                }
                if level.objectives:
                    rows[OBJECTIVES] = slice(tasks_end - row0, row_end - row0)
                irows = {
                    name: slice(a - ineq0, z - ineq0)
                    for lv, a, z, name in self._inequality_rows
                    if lv == li
                }
                levels.append(
                    LevelProblem(
                        level.name,
                        self._A[row0:row_end],
                        self._b[row0:row_end],
                        self._C[ineq0:ineq_end],
                        self._CB[0, ineq0:ineq_end],
                        self._CB[1, ineq0:ineq_end],
                        rows,
                        irows,
                        unweight=rw[1, row0:row_end],
                    )
                )
            box = self.view(lay.F_BOX)
            self._problem = StackProblem(levels, box[0], box[1], self.stack.scale, {})
        problem = self._problem
        problem.scale = self.stack.scale
        lf = self._level_f
        for li, lp in enumerate(problem.levels):
            lp.identity_scale = float(lf[li, lay.LEVEL_IDENTITY])
            lp.reference_scale = float(lf[li, lay.LEVEL_REFERENCE])
        problem.anchor = self.view(lay.F_ANCHOR) if self._has_anchor() else None
        return problem

    def _has_anchor(self) -> bool:
        """Whether a compiled acceleration limit sets the anchor."""
        return any(r.packed.kind == lay.KIND_ACCELERATION for r in self.compiled)

    def objective_values(self) -> dict[str, ObjectiveValue]:
        """Every objective's value, gradient and curvature at the last evaluation."""
        out: dict[str, ObjectiveValue] = {}
        grads, curvs = self.view(lay.F_OBJ_GRAD), self.view(lay.F_OBJ_CURV)
        for rec in self.objectives:
            o, j = rec.entry, rec.slot
            if rec.packed is None:
                out[o.name] = self._python_values[o.name]
            elif rec.packed.kind == lay.KIND_ARM:
                parts = rec.block[AE_WIDTH : AE_WIDTH + ARM_PARTS]
                value, gravity, spring, alpha, stiff, rho = parts.tolist()
                out[o.name] = ArmEnergyValue(
                    value, grads[j].copy(), None, gravity, spring, alpha, stiff, rho
                )
            else:
                curv = curvs[j].copy() if rec.packed.curvature else None
                out[o.name] = ObjectiveValue(float(self._obj[j, 1]), grads[j].copy(), curv)
        return out

    def arm_parts(self, energy: ArmPotentialEnergy, state: RobotState) -> np.ndarray | None:
        """``energy``'s parts (:meth:`ArmPotentialEnergy.parts`) as the last kernel evaluation
        computed them for a compiled arm energy of the stack with the same value, if that
        evaluation was at ``state``; else None."""
        if state.stamp != self.evaluated:
            return None
        for rec in self.objectives:
            kind = lay.KIND_PYTHON if rec.packed is None else rec.packed.kind
            if kind == lay.KIND_ARM and rec.entry.same_energy(energy):
                return rec.block[AE_WIDTH : AE_WIDTH + ARM_PARTS]
        return None


def kinematics_buffers(robot: Robot) -> tuple[control.Kinematics, bool]:
    """The packed model and the buffers of the kernels' own kinematics
    (:class:`~wholebody.kernels.control.Kinematics`), and whether the kernels can move the
    robot (else its joints need Pinocchio's kinematics, and the tables are empty)."""
    model = robot.model
    try:
        model_i, model_f = robot.kinematics.model_tables()
        movable = True
    except ModelError:
        model_i, model_f = np.zeros((0, 4), dtype=np.int64), np.zeros((0, 15))
        movable = False
    buffers = control.Kinematics(
        model_i,
        model_f,
        np.zeros((model.nv, 6)).T,
        np.zeros((model.nframes, 12)),
        np.zeros((model.njoints, 12)),
        np.zeros(model.nv),
    )
    return buffers, movable


class StepBuffers:
    """What a compiled step reads and writes besides the arena (:mod:`wholebody.kernels.
    control`): the arena as a record, the kinematics' buffers (Pinocchio's views, or the
    kernel's own with the packed model) and a batch of one state for ``references``
    references."""

    def __init__(self, plan: Plan, references: int) -> None:
        robot = self.robot = plan.robot
        self.arena = control.Arena(plan.f, plan.i, plan.h)
        self.own, self.movable = kinematics_buffers(robot)
        self.references = references
        self.batch = control.Batch(
            np.zeros((1, robot.nq)),
            np.zeros((1, references, REF_WIDTH)),
            np.zeros((1, robot.nu)),
            np.zeros((1, robot.nq)),
            np.zeros(1, dtype=np.int64),
            np.zeros((1, plan.view(lay.F_PAR).size)),
        )
        self._views: tuple[np.ndarray, np.ndarray] | None = None
        self._pinocchio: control.Kinematics | None = None

    def pinocchio(self) -> control.Kinematics:
        """The kinematics read from the robot's Pinocchio data (after :meth:`Robot.update`)."""
        views = self.robot.kinematics.views()
        if self._views is None or views[0] is not self._views[0] or views[1] is not self._views[1]:
            self._views = views
            self._pinocchio = self.own._replace(J=views[0], oMf=views[1])
        return self._pinocchio  # type: ignore[return-value]


class _Probe:
    """A packer that only knows the frames already laid out (an entry repacking itself must
    not add one: the stack is then laid out anew)."""

    def __init__(self, frames: dict[int, int]) -> None:
        self._frames = frames

    def frame(self, frame: Frame) -> int:
        return self._frames.get(frame.index, -2)


def is_compiled(entry: Entry) -> bool:
    """Whether the kernels compute ``entry`` themselves (else it runs in Python)."""
    frames: dict[int, int] = {}

    class _Any:
        def frame(self, frame: Frame) -> int:
            return frames.setdefault(frame.index, len(frames))

    return _pack(entry, _Any()) is not None


def _pack(entry: Entry, packer: Packer) -> Packed | None:
    """How the kernels compute ``entry``: its :meth:`~wholebody.tasks.Task.pack`, or None
    for a damped task (:meth:`~wholebody.tasks.Task.damp` runs in Python)."""
    if getattr(entry, "lm_damping", 0.0):
        return None
    return entry.pack(packer)
