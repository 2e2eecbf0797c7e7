"""The contracts between tasks, objectives, constraints and solvers.

Everything is at the velocity level, in the robot's **actuated velocity** ``u`` (size nu,
see :class:`wholebody.Robot`), for one control step of ``dt`` seconds:

* a :class:`Task` returns equality rows ``J u = v`` (:class:`TaskRows`): ``v`` already holds
  the feed-forward and the feedback correction, so "achieve the task" means "solve the rows";
* an :class:`InequalityTask` returns rows ``lower <= C u <= upper`` (:class:`InequalityRows`);
* an :class:`Objective` returns a cost ``f(q)`` and its gradient in actuated coordinates,
  ``g_k = d f / d t`` along ``u = e_k`` (:class:`ObjectiveValue`); a solver descends it;
* a :class:`Limit` returns a box ``lower <= u <= upper`` (:class:`Bounds`) that every
  level must respect (what pink and mink call limits too).

Tasks never call solvers and solvers know tasks only through these contracts.

Two optional hooks serve the control loop's speed, never its results: ``jacobian_frames()``
lists the frames whose Jacobians an entry reads (a :class:`~wholebody.solvers.Stack` computes
them in one batch before evaluating its entries), and :meth:`Task.write_rows` writes a task's
rows into a caller's buffer instead of allocating them.

**Compiled entries.** The built-in entries are computed by the compiled core: each one packs
itself (:meth:`Task.pack`) into what its kernel reads, a parameter block of floats laid out by
that kernel (:class:`Packed`), which holds the entry's settings and state (a pose task's
gains, target, integral and last error). The stack copies the block into its arena and the
entry :meth:`~Task.adopt` s the copy, so that the entry and the kernels share one memory: a
new target set in Python is what the next step reads, an integral advanced by the kernel is
what the task reports. An entry of your own runs in Python (``pack`` returns None).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from wholebody.errors import DimensionError
from wholebody.robot import Frame, RobotState

__all__ = [
    "Bounds",
    "InequalityRows",
    "InequalityTask",
    "Limit",
    "Objective",
    "ObjectiveValue",
    "Packed",
    "Packer",
    "Task",
    "TaskRows",
    "damp_rows",
]


@dataclass(frozen=True)
class TaskRows:
    """Equality rows ``J u = v`` with non-negative per-row weights.

    Within one level the solvers minimise ``sum_i weights_i (J_i u - v_i)^2``.
    """

    J: np.ndarray  # (m, nu)
    v: np.ndarray  # (m,)
    weights: np.ndarray  # (m,)


@dataclass(frozen=True)
class InequalityRows:
    """Inequality rows ``lower <= C u <= upper`` (entries may be infinite)."""

    C: np.ndarray  # (m, nu)
    lower: np.ndarray  # (m,)
    upper: np.ndarray  # (m,)


@dataclass(frozen=True)
class Bounds:
    """A box on the actuated velocity: ``lower <= u <= upper`` (rad/s, m/s; may be inf)."""

    lower: np.ndarray  # (nu,)
    upper: np.ndarray  # (nu,)


@dataclass(frozen=True)
class ObjectiveValue:
    """A cost, its gradient in actuated coordinates (``d cost / d u``-direction) and,
    optionally, a non-negative estimate of the diagonal of its Hessian (``curvature``), which
    makes the descent step semi-implicit (see :mod:`wholebody.solvers.stack`)."""

    value: float
    gradient: np.ndarray  # (nu,)
    curvature: np.ndarray | None = None  # (nu,) >= 0, or None when not available


_NO_INTS = np.zeros(0, dtype=np.int64)
_NO_INTS.setflags(write=False)


@dataclass(frozen=True)
class Packed:
    """How the compiled core computes an entry (:meth:`Task.pack`).

    ``kind`` names its kernel (``KIND_*`` of :mod:`wholebody.kernels.layout`); ``floats`` is
    the entry's own parameter block, laid out by that kernel (the stack copies it into its
    arena and hands the copy back through :meth:`Task.adopt`); ``ints`` are its integer
    parameters, frames given as rows of the stack's frame table (:meth:`Packer.frame`);
    ``curvature`` (objectives) says that its gradient comes with a Hessian diagonal.
    """

    kind: int
    floats: np.ndarray
    ints: np.ndarray = field(default_factory=lambda: _NO_INTS)
    curvature: bool = False


class Packer(Protocol):
    """What an entry may ask the stack for while it packs itself."""

    def frame(self, frame: Frame) -> int:
        """The row of ``frame`` in the stack's frame table (its kinematics are computed
        each step: position, rotation, Jacobian in actuated coordinates)."""
        ...


class Compiled:
    """The part of the entry contract the compiled core uses (see the module docstring):
    :meth:`pack` and :meth:`adopt`. An entry that keeps its numbers in ``self._params`` (a
    float array laid out by its kernel) needs only :meth:`pack`."""

    _params: np.ndarray

    def pack(self, packer: Packer) -> Packed | None:
        """How the kernels compute this entry, or None: it is evaluated in Python (the
        default, and what an entry of your own gets)."""
        return None

    def adopt(self, block: np.ndarray) -> None:
        """From now on keep the parameter block in ``block``, a stack's copy of it."""
        self._params = block

    def check_step(self, dt: float) -> None:
        """Raise an error naming the entry if it cannot take a step of ``dt`` s (the stack
        asks whenever ``dt`` changes)."""

    def compiled_as(self, cls: type, *methods: str) -> bool:
        """Whether ``type(self)`` keeps ``cls``'s ``methods`` (a subclass that overrides one
        of them changes what the entry computes: it is evaluated in Python)."""
        return all(getattr(type(self), m) is getattr(cls, m) for m in methods)


def check_name(name: object, kind: str) -> str:
    """A task's, objective's or limit's name: a non-empty string, or DimensionError."""
    if not (isinstance(name, str) and name):
        raise DimensionError(f"{kind} name must be a non-empty string, got {name!r}")
    return name


def check_weight(weight: object, name: str) -> float | np.ndarray:
    """A weight: a finite number >= 0 or a 1-D array of them (read-only), or DimensionError
    naming the owner."""
    if isinstance(weight, bool):
        raise DimensionError(f"{name}: weight must be a number >= 0 or one per row, got {weight!r}")
    if isinstance(weight, (int, float, np.floating, np.integer)):
        w = float(weight)
        if not (math.isfinite(w) and w >= 0):
            raise DimensionError(f"{name}: weight must be finite and >= 0, got {weight!r}")
        return w
    try:
        arr = np.array(weight, dtype=float)
    except (TypeError, ValueError):
        raise DimensionError(
            f"{name}: weight must be a number >= 0 or one per row, got {weight!r}"
        ) from None
    if arr.ndim != 1 or not (np.all(np.isfinite(arr)) and np.all(arr >= 0)):
        raise DimensionError(
            f"{name}: weight must be a number >= 0 or one per row (finite, >= 0), got {weight!r}"
        )
    arr.setflags(write=False)
    return arr


class Task(Compiled, ABC):
    """Equality rows ``J u = v`` at the velocity level.

    The short way to write one (pink's): say the number of rows (:attr:`dim`), the error
    ``e(q)`` the task drives to zero (:meth:`compute_error`) and its Jacobian ``J = de/du`` in
    actuated coordinates (:meth:`compute_jacobian`, so that ``de/dt = J u``). The base class
    then asks for the first-order decay ``de/dt = -gain e``: the rows ``J u = -gain e``
    (:meth:`compute`), their shapes and values checked on the first call, with an error that
    names the task and the method. For full control (a feed-forward term, an integral, rows
    that are not an error's derivative) override :meth:`compute` instead.

    Subclasses call ``super().__init__(name, weight, gain=...)`` (all checked).

    A task may be damped (``lm_damping``, pink's): a Levenberg-Marquardt term ``mu =
    lm_damping * sum_i w_i e_i^2`` (``w`` its weights, ``e`` its :meth:`error`) that makes
    the task ask for less where its Jacobian is ill-conditioned and its error large. The stack
    applies it to the task's own rows when it assembles the level
    (:func:`~wholebody.tasks.damp_rows`): their right-hand side becomes ``v_mu = S^-1 G (G +
    mu I)^-1 S v`` (``S = diag(sqrt w)``, ``G = S J J^T S``), so that a task alone in its
    level, no bound active, moves exactly as pink's damped QP, ``u = (J^T W J + mu I)^-1 J^T
    W v``, on every backend; and the directions the task does not use stay free for the levels
    below it (a damping term on ``u`` inside the level would take them). A built-in task with
    damping is evaluated in Python.

    Attributes
    ----------
    name
        Unique within a stack; used in logs, results and error messages.
    weight
        Scalar or per-row weight inside its level (relative importance among the tasks of
        one level; priorities between levels are strict): finite, >= 0.
    gain
        The decay rate of the error with the short way (1/s): ``de/dt = -gain e``, the error
        shrinking by a factor e every ``1 / gain`` s while the task is met. Not used by a
        task that overrides :meth:`compute`.
    lm_damping
        The Levenberg-Marquardt damping above (in units of ``1 / e^2`` times those of ``J^T W
        J``; 0, the default: none): finite, >= 0.
    """

    _lm_damping = 0.0  # (a subclass that does not call __init__ is undamped)

    def __init__(
        self,
        name: str,
        weight: float | Sequence[float] | np.ndarray = 1.0,
        *,
        gain: float = 10.0,
        lm_damping: float = 0.0,
    ) -> None:
        self.name = check_name(name, type(self).__name__)
        self.weight = weight
        self.lm_damping = lm_damping
        if not (isinstance(gain, (int, float)) and math.isfinite(gain) and gain >= 0):
            raise DimensionError(
                f"{self.name}: gain must be a finite number >= 0 (1/s), got {gain!r}"
            )
        self.gain = float(gain)
        self._checked = False

    @property
    def weight(self) -> float | np.ndarray:
        """Scalar or per-row weight in its level (finite, >= 0; arrays are read-only)."""
        return self._weight

    @weight.setter
    def weight(self, value: float | Sequence[float] | np.ndarray) -> None:
        self._weight = check_weight(value, getattr(self, "name", type(self).__name__))

    @property
    def lm_damping(self) -> float:
        """The Levenberg-Marquardt damping (finite, >= 0; class docstring)."""
        return self._lm_damping

    @lm_damping.setter
    def lm_damping(self, value: float) -> None:
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
            name = getattr(self, "name", type(self).__name__)
            raise DimensionError(f"{name}: lm_damping must be a finite number >= 0, got {value!r}")
        self._lm_damping = float(value)

    def damp(self, state: RobotState, J: np.ndarray, v: np.ndarray, weights: object) -> None:
        """Damp the rows ``J u = v`` at ``state`` (weights as :meth:`write_rows` returns them)
        in place: ``v`` becomes :func:`~wholebody.tasks.damp_rows`'s with ``mu =
        lm_damping * sum w e^2``."""
        e = np.asarray(self.error(state), dtype=float)
        w = np.broadcast_to(np.asarray(weights, dtype=float), v.shape)
        if e.shape != v.shape or not np.isfinite(e).all():
            raise DimensionError(
                f"{self.name}: lm_damping needs the task's error, (dim,) and finite (define "
                f"compute_error or error); got shape {e.shape}"
            )
        v[:] = damp_rows(J, v, w, self.lm_damping * float(w @ (e * e)))

    @property
    def weights(self) -> np.ndarray:
        """The weight of each row, shape ``(dim,)`` (DimensionError if a per-row weight has
        another length)."""
        w = self.weight
        if isinstance(w, float):
            return np.full(self.dim, w)
        if w.shape != (self.dim,):
            raise DimensionError(f"{self.name}: {w.size} weights for {self.dim} rows")
        return w.copy()

    @property
    @abstractmethod
    def dim(self) -> int:
        """Number of rows."""

    def compute_error(self, state: RobotState) -> np.ndarray:
        """The error ``e`` (dim,) at ``state`` that the task drives to zero (the short way)."""
        raise NotImplementedError(
            f"{type(self).__name__}: define compute_error and compute_jacobian, or compute"
        )

    def compute_jacobian(self, state: RobotState) -> np.ndarray:
        """``J = de/du`` (dim x nu) at ``state``, in actuated coordinates (the short way)."""
        raise NotImplementedError(
            f"{type(self).__name__}: define compute_error and compute_jacobian, or compute"
        )

    def compute(self, state: RobotState) -> TaskRows:
        """The rows at ``state``: by default ``J u = -gain e`` from :meth:`compute_error` and
        :meth:`compute_jacobian`."""
        e = np.asarray(self.compute_error(state), dtype=float)
        J = np.asarray(self.compute_jacobian(state), dtype=float)
        if not self._checked:
            self._check_short(state, e, J)
        return TaskRows(J, -self.gain * e, self.weights)

    def _check_short(self, state: RobotState, e: np.ndarray, J: np.ndarray) -> None:
        """The first call's check of the short way's shapes and values."""
        nu = state.robot.nu
        if e.shape != (self.dim,):
            raise DimensionError(
                f"{self.name}: compute_error returned shape {e.shape}, expected ({self.dim},) (dim)"
            )
        if J.shape != (self.dim, nu):
            raise DimensionError(
                f"{self.name}: compute_jacobian returned shape {J.shape}, "
                f"expected ({self.dim}, {nu}) (dim, nu)"
            )
        if not (np.isfinite(e).all() and np.isfinite(J).all()):
            raise DimensionError(
                f"{self.name}: compute_error or compute_jacobian is not finite at the first state"
            )
        self._checked = True

    def write_rows(self, state: RobotState, J: np.ndarray, v: np.ndarray) -> float | np.ndarray:
        """Write the rows at ``state`` into ``J`` (dim x nu) and ``v`` (dim,) and return their
        weights (a scalar or one per row): :meth:`compute` without its allocations, for the
        stack's buffers. The default copies :meth:`compute`'s result, its shapes checked
        (DimensionError naming the task: numpy would broadcast a row over all rows)."""
        rows = self.compute(state)
        check_rows(self.name, rows.J, rows.v, J.shape)
        J[...] = rows.J
        v[...] = rows.v
        return rows.weights

    def jacobian_frames(self) -> tuple[Frame, ...]:
        """Frames whose Jacobians :meth:`compute` reads (for batching; may be incomplete)."""
        return ()

    def error(self, state: RobotState) -> np.ndarray:
        """The task error at ``state`` (what the feedback drives to zero), for logging: the
        short way's :meth:`compute_error`. A task that defines neither logs NaN (not a zero
        that would read as "met")."""
        if type(self).compute_error is not Task.compute_error:
            return np.asarray(self.compute_error(state), dtype=float)
        return np.full(self.dim, np.nan)

    def advance(self, state: RobotState, dt: float, saturated: bool = False) -> None:
        """Advance internal state (integrators) by one control step of ``dt`` seconds, after
        the step was solved at ``state``. ``saturated`` tells that the hard constraints kept
        the solver from realising this task's rows (a bound active on a joint they move, its
        level scaled, or the task unmet: :meth:`~wholebody.solvers.Stack.saturated_tasks`),
        for anti-windup."""

    def reset(self) -> None:
        """Forget internal state (integrators)."""


def damp_rows(J: np.ndarray, v: np.ndarray, w: np.ndarray, mu: float) -> np.ndarray:
    """The right-hand side ``v_mu = S^-1 G (G + mu I)^-1 S v`` of the rows ``J u = v`` (m x
    n, m) of weights ``w`` (m, >= 0; ``S = diag(sqrt w)``, ``G = S J J^T S``) damped by ``mu
    >= 0``: the minimum-norm solution of ``S J u = S v_mu`` is the Levenberg-Marquardt step
    ``J^T S (G + mu I)^-1 S v = (J^T W J + mu I)^-1 J^T W v``. Rows of weight 0 keep ``v``."""
    if mu <= 0.0:
        return v.copy()
    s = np.sqrt(w)
    Js, vs = J * s[:, None], v * s
    G = Js @ Js.T
    G[np.diag_indices_from(G)] += mu
    out = v.copy()
    kept = s > 0.0
    out[kept] = (vs - mu * np.linalg.solve(G, vs))[kept] / s[kept]
    return out


class InequalityTask(Compiled, ABC):
    """Inequality rows ``lower <= C u <= upper`` at the velocity level."""

    name: str

    @property
    @abstractmethod
    def dim(self) -> int:
        """Number of rows."""

    @abstractmethod
    def compute(self, state: RobotState, dt: float) -> InequalityRows:
        """The rows at ``state`` for a step of ``dt`` seconds."""

    def jacobian_frames(self) -> tuple[Frame, ...]:
        """Frames whose Jacobians :meth:`compute` reads (for batching; may be incomplete)."""
        return ()


class Objective(Compiled, ABC):
    """A scalar cost of the configuration with its analytic gradient.

    Attributes
    ----------
    name
        Unique within a stack.
    weight
        The objective's coefficient in its level's sum ``H = sum_i weight_i f_i`` (a
        negative weight maximises, as the paper's manipulability term).
    """

    def __init__(self, name: str, weight: float = 1.0) -> None:
        self.name = check_name(name, type(self).__name__)
        if isinstance(weight, bool) or not isinstance(weight, (int, float, np.floating)):
            raise DimensionError(f"{name}: weight must be a finite number, got {weight!r}")
        if not math.isfinite(weight):
            raise DimensionError(f"{name}: weight must be a finite number, got {weight!r}")
        self.weight = float(weight)

    @abstractmethod
    def evaluate(self, state: RobotState) -> ObjectiveValue:
        """Cost and gradient (unweighted) at ``state``."""

    def jacobian_frames(self) -> tuple[Frame, ...]:
        """Frames whose Jacobians :meth:`evaluate` reads (for batching; may be incomplete)."""
        return ()


class Limit(Compiled, ABC):
    """A hard box on the actuated velocity for one control step (what pink and mink call a
    limit too)."""

    name: str

    @abstractmethod
    def bounds(self, state: RobotState, dt: float) -> Bounds:
        """The box at ``state`` for a step of ``dt`` seconds."""

    def advance(self, u: np.ndarray, dt: float) -> None:
        """After a step: the velocity ``u`` that was applied for ``dt`` s (a constraint with
        a memory, such as :class:`~wholebody.tasks.AccelerationLimits`, keeps it)."""

    def reset(self) -> None:
        """Forget what :meth:`advance` kept (a new run starts at rest)."""


def check_rows(name: str, J: np.ndarray, v: np.ndarray, shape: tuple[int, ...]) -> None:
    """Rows ``J`` (m x nu) and ``v`` (m,) of task ``name`` as its buffer ``shape`` expects, or
    DimensionError naming the task."""
    J, v = np.asarray(J), np.asarray(v)
    if J.shape != shape or v.shape != shape[:1]:
        raise DimensionError(
            f"task {name!r}: compute() returned J {J.shape} and v {v.shape}; "
            f"expected J {shape} and v ({shape[0]},) (dim x nu)"
        )
