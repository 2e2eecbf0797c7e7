"""The solver contract, and the settings a solver keeps where its kernels read them."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from wholebody.errors import SolverError
from wholebody.robot import RobotState
from wholebody.solvers.plan import BoundCall, first_call
from wholebody.solvers.result import SolverResult
from wholebody.solvers.stack import Stack

if TYPE_CHECKING:
    from wholebody.kernels import control
    from wholebody.solvers.plan import Arena, Plan

__all__ = ["Setting", "Solver"]


class Setting:
    """A solver's setting stored in its kernels' parameter vector (``solver._par[index]``), so
    that a step passes the vector as it is: checked when it is set, not on every step.

    ``kind`` (float, int or bool) is what reading it gives; ``valid(value)`` says whether a
    finite value is accepted, ``rule`` how to say it in the error."""

    def __init__(
        self,
        index: int,
        kind: type = float,
        valid: Callable[[float], bool] | None = None,
        rule: str = "",
    ) -> None:
        self.index, self.kind, self.valid, self.rule = index, kind, valid, rule
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return self.kind(obj._par[self.index])

    def __set__(self, obj: Any, value: object) -> None:
        try:
            number = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            number = math.nan
        if self.kind is not bool and (
            not math.isfinite(number)
            or (self.valid is not None and not self.valid(number))
            or (self.kind is int and number != int(number))
        ):
            raise SolverError(
                f"{type(obj).__name__}: {self.name} must be a finite {self.kind.__name__} "
                f"{self.rule}, got {value!r}".rstrip()
            )
        obj._par[self.index] = bool(value) if self.kind is bool else number


class Solver(ABC):
    """A solver backend: turns a :class:`Stack` at a state into an actuated velocity.

    Its kernels run on a stack's :class:`~wholebody.solvers.plan.Plan`: :meth:`run` does
    whole steps on it (the kernel's bits, :mod:`wholebody.kernels.control`), :meth:`result`
    reads the outcome; :meth:`solve` is the step written out for one state."""

    name: str
    _par: np.ndarray  # the settings (:class:`Setting`) as the kernels read them

    @abstractmethod
    def solve(self, stack: Stack, state: RobotState, dt: float) -> SolverResult:
        """The actuated velocity ``u`` for one control step of ``dt`` seconds at ``state``.

        Never returns NaN; ``u`` always respects the stack's constraints (box).
        """

    @abstractmethod
    def run(
        self,
        plan: Plan,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
    ) -> None:
        """``steps`` steps of each state of ``batch`` on the synced ``plan``."""

    @abstractmethod
    def result(self, arena: Arena, solve_time: float, stack: Stack | None = None) -> SolverResult:
        """The outcome of the last :meth:`run` in ``arena`` (a plan) as a result."""

    def kernel_run(
        self,
        arena: Arena,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
        workspace: control.Arena | None,
    ) -> None:
        """``steps`` steps of each state of ``batch`` in one call of the solver's step kernel
        (:meth:`_kernel_call`) on an arena (a plan's, or a copy of it: a thread's share of a
        batch) and its workspace (None where the kernel takes none)."""
        first_call(*self._kernel_call(arena, workspace, kinematics, batch, steps, what))

    def stepper(
        self, plan: Plan, kinematics: control.Kinematics, batch: control.Batch, what: int
    ) -> Callable[[], None]:
        """One step of the batch's first state on ``plan``, as a call without arguments (what
        :meth:`wholebody.control.Controller.step` makes every period): the step kernel with
        its arguments bound (:class:`~wholebody.solvers.plan.BoundCall`; the settings are
        read from their vector at each call)."""
        arena = plan.step_buffers(batch.refs.shape[1]).arena
        workspace = self._step_workspace(plan)
        return BoundCall(*self._kernel_call(arena, workspace, kinematics, batch, 1, what))

    def _step_workspace(self, plan: Plan) -> control.Arena | None:
        """The workspace the step kernel takes for ``plan`` (None: it takes none)."""
        return None

    @abstractmethod
    def _kernel_call(
        self,
        arena: Arena,
        workspace: control.Arena | None,
        kinematics: control.Kinematics,
        batch: control.Batch,
        steps: int,
        what: int,
    ) -> tuple[Any, ...]:
        """The step kernel's name, notice, dispatcher and arguments (for
        :func:`~wholebody.solvers.plan.first_call` and
        :class:`~wholebody.solvers.plan.BoundCall`)."""
