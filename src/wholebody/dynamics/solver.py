r"""The torque-level backend: accelerations, torques and contact wrenches from the same
task objects as the velocity backends.

Variables and equations
-----------------------
The unknowns are the actuated acceleration ``a`` (nu; the model's is ``dv = A a`` with the
constant actuation matrix ``A``, :mod:`wholebody.robot.actuation`) and the wrench ``f_c`` of
every active contact (:mod:`wholebody.dynamics.contacts`). The actuators' generalised force
follows from them through the equations of motion,

.. math::

    Q = M(q)\,A a + h(q, v) - \sum_c J_c^T f_c \qquad (nv), \qquad
    \tau = A^T Q \qquad (nu),

``Q`` being what the motors apply to the model's velocities (zero on a floating base's six:
those rows are equalities) and ``tau`` its work-conjugate on ``u`` (a wheel's torque for a
wheel speed). The torques are thus not free variables: eliminating them keeps the problem
small and makes ``M dv + h = S^T tau + sum J_c^T f`` hold exactly. ``M`` and ``h`` are the
rigid bodies' (Pinocchio's) plus each drive's rotor inertia on the diagonal and viscous
friction ``d v`` (robot.toml ``[sim] armature`` and ``damping``: what the MuJoCo model
simulates and a real drive has; 0 in ``[sim]`` for the rigid bodies alone).

Tasks in acceleration form
--------------------------
A stack's level gives rows ``J u = b`` (:meth:`wholebody.solvers.Stack.evaluate`): ``b`` is
the velocity the task wants now (its reference's twist less its gain times its error). At
the torque level the same rows ask for the acceleration that brings ``J u`` to ``b``:

.. math::

    J a = K_d\,(b - J u) + \dot b - \dot J u

with ``K_d`` the ``velocity_gain`` (1/s) and ``b'`` the rate of ``b`` (its change since the
last step over ``dt``; ``feedforward``): ``J u`` then follows ``b`` with the time constant
``1 / K_d`` and no lag, and a task ``e' = v_ref - k e`` keeps its velocity-level behaviour
(without ``b'`` it is the PD law ``e'' + K_d e' + K_d k e = 0``). ``Jdot u`` is the
derivative of the rows along the motion, by a forward difference of the stack's own rows at
``q`` and ``q (+) eps u`` for every task, built-in or a user's (``eps`` such that no
coordinate moves more than :data:`DRIFT_STEP`; its error is about 1e-8 relative, checked
against Pinocchio's frame accelerations in the tests). An inequality row ``l <= C u' <= h``
on the next velocity ``u' = u + a dt`` becomes ``(l - C u)/dt <= C a <= (h - C u)/dt``; so
does the stack's box (velocity limits, position limits for one step), intersected with the
braking bounds of the joint position limits (:mod:`wholebody.dynamics.braking`) and the
robot's acceleration limits; a floating base's six are left free (the contacts and the
joints move them).

Priorities
----------
Level 0 holds the equations of motion of the unactuated velocities (a floating base's six),
level 1 the contacts (their acceleration rows, and as inequality rows their wrench cones and
centres of pressure, and the torque limits ``|tau_j| <= effort_j``), then the contacts'
wrench targets if any (force tasks, :meth:`Contact.set_wrench_target
<wholebody.dynamics.contacts.Contact.set_wrench_target>`), then the stack's levels
in order, and last the contacts' tangential forces and torques kept small where nothing above
decides them (the load shared between contacts with the centres of pressure central).
``mode="strict"`` solves them as a strict hierarchy with the hierarchical QP (the cascade,
:class:`~wholebody.solvers.HierarchicalQPSolver`); ``mode="weighted"`` keeps levels 0 and 1
and the last strict and sums the stack's levels into one, level ``k``'s rows times
``level_weights[k]``. Each stack level's rows are divided by ``max(1, ||b||)`` (the same
optimum), so that the cascade's tolerances, relative to a level's residual, stay tight on the
contact and torque rows every level inherits: they hold to about 1e-9 of the robot's weight.
Wrenches are scaled by the robot's weight ``m g`` inside the QP, so the final minimum-norm
choice weighs ``||a||^2`` against ``||f / (m g)||^2``.

Nothing saturates silently: after each solve :attr:`DynamicsResult.violations` holds, per
kind of bound, how far the answer exceeds it (torques in N m or N, wrench rows in N or N m,
the equations of motion in N m), and the status is INFEASIBLE, with the contact or the
torque named, when any exceeds ``tolerance``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import scipy.linalg

from wholebody.dynamics.braking import braking_bounds
from wholebody.dynamics.carry import CarriedObject, GraspRows
from wholebody.dynamics.contacts import Contact, ContactRows
from wholebody.dynamics.result import DynamicsResult
from wholebody.dynamics.rows import Rows, equality_level, padded, with_rows
from wholebody.errors import ConfigError, DimensionError, SolverError
from wholebody.kernels import layout as lay
from wholebody.robot import Robot, RobotState
from wholebody.robot.sim import effort_limits
from wholebody.solvers import compiled_hqp
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.plan import ProblemArena
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import OBJECTIVES, Stack, StackProblem
from wholebody.tasks.limits import AccelerationLimits

__all__ = ["DynamicsResult", "DynamicsSolver"]

GRAVITY = 9.81
"""m/s^2, the scale of the wrenches inside the QP (the robot's weight)."""
DRIFT_STEP = 1e-8
"""rad or m: the largest coordinate change of the forward difference that gives ``Jdot u``."""


@dataclass
class _Physics:
    """The robot's dynamics at ``(q, v)``: ``M`` (nv x nv), ``h`` (nv), and each active
    contact's rows."""

    M: np.ndarray
    h: np.ndarray
    contacts: list[ContactRows]
    grasps: list[GraspRows]

    def jacobians(self) -> list[np.ndarray]:
        """Each wrench's Jacobian (k x nv), in the order of the unknowns: the contacts', then
        each carried object's hands'."""
        return [c.jacobian for c in self.contacts] + [J for g in self.grasps for J in g.jacobians]


def _checked_gain(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ConfigError(f"DynamicsSolver: {name} must be a finite positive number, got {value}")
    return value


class DynamicsSolver:
    """The torque-level backend (module docstring).

    Parameters
    ----------
    robot
        The robot; its URDF's effort limits (times ``[sim] effort_scale``) bound the torques.
    contacts
        The active contacts (:class:`~wholebody.dynamics.PatchContact`,
        :class:`~wholebody.dynamics.PointContact`); :meth:`make_contacts` holds them where
        they are.
    mode
        ``"strict"`` (a strict hierarchy over the stack's levels) or ``"weighted"``.
    velocity_gain
        ``K_d`` (1/s) of the tasks' acceleration form.
    braking
        Deceleration (rad/s^2, m/s^2) the joint position limits keep in reserve.
    feedforward
        Add the rate of each row's wanted velocity ``b`` (its change since the last step over
        ``dt``) to the row's acceleration: a moving reference's acceleration, which the
        velocity rows do not hold, so that ``J u`` follows ``b`` without lag.
    acceleration_limits
        Bound each actuated acceleration by the robot's acceleration limits
        (:attr:`~wholebody.robot.Robot.acceleration_limits`, robot.toml ``[acceleration]``).
        A stack's own :class:`~wholebody.tasks.AccelerationLimits` are refused: they bound
        the next velocity about the last command, which at the torque level is not the
        measured velocity.
    level_weights
        ``mode="weighted"``: the weight of each stack level's rows (default 1 for every
        level: the tasks' own weights decide).
    wrench_regularization
        Weight, inside every level of the stack, of the contacts' internal tangential forces
        and torques (in units of the robot's weight: the part of the wrenches whose sum is
        zero, which pushes the contacts against each other and which no task needs) against
        the level's own rows: a level whose optimum leaves them free then takes the quietest,
        not a vertex of their cones, which the levels below would inherit (0: only the last
        level chooses them).
    tolerance
        Excess over a bound (N m, N) that makes the step INFEASIBLE.
    engine
        The hierarchical QP's engine (``"daqp"`` by default).
    """

    name = "dynamics"

    def __init__(
        self,
        robot: Robot,
        contacts: Iterable[Contact] = (),
        *,
        mode: str = "strict",
        velocity_gain: float = 20.0,
        braking: float = 10.0,
        acceleration_limits: bool = True,
        feedforward: bool = True,
        level_weights: Sequence[float] | None = None,
        wrench_regularization: float = 1e-3,
        tolerance: float = 1e-3,
        engine: str = "daqp",
    ) -> None:
        if mode not in ("strict", "weighted"):
            raise ConfigError(f"DynamicsSolver: mode must be 'strict' or 'weighted', got {mode!r}")
        self.robot, self.mode = robot, mode
        self.velocity_gain = _checked_gain("velocity_gain", velocity_gain)
        self.braking = _checked_gain("braking", braking)
        self.acceleration_limits = bool(acceleration_limits)
        self.feedforward = bool(feedforward)
        self._last_b: list[np.ndarray] | None = None
        self._stack: Stack | None = None
        self.level_weights = None if level_weights is None else [float(w) for w in level_weights]
        self.wrench_regularization = float(wrench_regularization)
        if not (math.isfinite(self.wrench_regularization) and self.wrench_regularization >= 0):
            raise ConfigError(
                f"DynamicsSolver: wrench_regularization must be >= 0, got {wrench_regularization}"
            )
        self.tolerance = _checked_gain("tolerance", tolerance)
        model = robot.model
        self._data = model.createData()
        self._A = np.asarray(robot.actuation)
        # a floating base's six velocities have no motor: the entries of u that move them
        root = self._A[:6] if robot.base.floating else self._A[:0]
        self._unactuated = np.flatnonzero(np.abs(root).sum(axis=0) > 0)
        self.effort = _actuator_limits(self._A, effort_limits(robot, robot.sim_settings))
        """The torque limit of each entry of ``u`` (N m, N: a joint's, a wheel's; inf for a
        floating base's six, which have no motor)."""
        self._driven = np.setdiff1d(np.flatnonzero(np.isfinite(self.effort)), self._unactuated)
        lower, upper = robot.position_limits
        self._limited = np.flatnonzero(np.isfinite(lower) | np.isfinite(upper))
        self.force_scale = float(sum(i.mass for i in model.inertias)) * GRAVITY
        sim = robot.sim_settings
        driven = np.ones(model.nv)
        driven[: 6 if robot.base.floating else 0] = 0.0
        self.rotor_inertia = sim.armature * driven
        """Per model velocity, the drive's rotor inertia added to ``M``'s diagonal (kg m^2,
        kg: robot.toml ``[sim] armature``, as MuJoCo simulates it)."""
        self.friction = sim.damping * driven
        """Per model velocity, the drive's viscous friction added to ``h`` (N m s/rad, N s/m:
        ``[sim] damping``)."""
        self.qp = HierarchicalQPSolver(engine, bound_relaxation=1e-12, stall_damping=0.0)
        self._arena: ProblemArena | None = None
        self._layout: tuple | None = None
        self._solves, self._eps = 0, 0.0
        self._quiet_key: tuple | None = None
        self._quiet_cache: tuple[np.ndarray, np.ndarray, np.ndarray]
        self.state: RobotState | None = None
        """The kinematics at the last solve's ``q`` (valid until the robot's next update):
        what the stack's :meth:`~wholebody.solvers.Stack.advance` takes after the step."""
        self.contacts: list[Contact] = []
        self.objects: list[CarriedObject] = []
        """The carried objects (:meth:`carry`, :mod:`wholebody.dynamics.carry`)."""
        for contact in contacts:
            self.add_contact(contact)

    def add_contact(self, contact: Contact) -> None:
        """Make ``contact`` active (its frame checked against the robot)."""
        if any(c.frame == contact.frame for c in self.contacts):
            raise ConfigError(f"DynamicsSolver: a contact on {contact.frame!r} is already active")
        contact.bind(self.robot.model)
        self.contacts.append(contact)

    def remove_contact(self, frame: str) -> Contact:
        """Break the contact on ``frame``; returns it."""
        for i, c in enumerate(self.contacts):
            if c.frame == frame:
                return self.contacts.pop(i)
        raise ConfigError(f"DynamicsSolver: no active contact on {frame!r}")

    def carry(self, obj: CarriedObject, q: np.ndarray, pose: np.ndarray) -> None:
        """Hold ``obj`` at ``pose`` (4x4, world, at its centre of mass) with its hands where
        they are at ``q``; it replaces an object of the same name."""
        obj.bind(self.robot.model)
        self.release(obj.name, missing_ok=True)
        pin.framesForwardKinematics(self.robot.model, self._data, np.asarray(q, dtype=float))
        obj.hold(self._data, pose)
        self.objects.append(obj)

    def release(self, name: str, missing_ok: bool = False) -> CarriedObject | None:
        """Let go of the carried object ``name``; returns it."""
        for i, o in enumerate(self.objects):
            if o.name == name:
                return self.objects.pop(i)
        if not missing_ok:
            raise ConfigError(f"DynamicsSolver: no carried object {name!r}")
        return None

    def _wrench_count(self) -> int:
        return sum(c.size for c in self.contacts) + sum(o.size for o in self.objects)

    def _grasp_rows(
        self, obj: CarriedObject, g: GraspRows, col: int, n: int
    ) -> tuple[dict[str, np.ndarray], list[np.ndarray], np.ndarray]:
        """A carried object's rows over ``x~`` (its wrenches at columns ``col``...): the
        equalities by name (its equations of motion and closure in N and m/s^2, the squeeze
        task), their right-hand sides, and the friction rows (``<= 0``)."""
        nu, fs, k = self.robot.nu, self.force_scale, obj.size
        E = np.zeros((6, n))
        E[:, :nu] = g.E_dv @ self._A / fs
        E[:, col : col + k] = g.E_f
        eq, b = {f"carry {obj.name}": E}, [g.e / fs]
        if g.K.shape[0]:
            K = np.zeros((g.K.shape[0], n))
            K[:, :nu] = g.K @ self._A
            eq[f"closure {obj.name}"], b = K, [*b, g.k]
        if obj.squeeze is not None:
            S = np.zeros((1, n))
            S[0, col : col + k] = g.squeeze
            eq[f"squeeze {obj.name}"], b = S, [*b, np.array([obj.squeeze / fs])]
        C = np.zeros((g.C.shape[0], n))
        C[:, col : col + k] = g.C
        return eq, b, C

    @property
    def contacts_made(self) -> bool:
        """Whether every active contact has been made (:meth:`make_contacts`)."""
        return all(c.reference is not None for c in self.contacts)

    def make_contacts(self, q: np.ndarray) -> None:
        """Hold every active contact where its frame is at ``q``."""
        model, data = self.robot.model, self._data
        pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
        for c in self.contacts:
            c.make(model, data)

    # ------------------------------------------------------------------ the step
    def solve(self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float) -> DynamicsResult:
        """The accelerations, torques and wrenches of one control step of ``dt`` seconds at
        the configuration ``q`` and actuated velocity ``u`` (rad/s, m/s)."""
        t0 = time.perf_counter()
        q, u = self._checked(stack, q, u, dt)
        if stack is not self._stack:  # another stack: its rows' rates start anew
            self._stack, self._last_b = stack, None
        drifts = self._task_drifts(stack, q, u, dt)
        self.state = state = self.robot.update(q)
        problem = stack.evaluate(state, dt)
        drifts = self._drift_rows(problem, u, drifts)
        physics = self._physics(q, self._A @ u)
        levels = self._task_levels(problem, u, drifts, dt)
        box = self._box(problem, q, u, dt)
        x, status = self._run(self._cascade(physics, levels, box))
        result = self._result(physics, x, status)
        result.solve_time = time.perf_counter() - t0
        return result

    def _run(self, problem: StackProblem) -> tuple[np.ndarray, SolverStatus]:
        """The cascade's kernel on ``problem`` (of :class:`Rows`), in an arena laid out at
        the first step and whenever the problem's shape changes, filled in place
        otherwise; the answer ``[a, f]`` and the status."""
        key = tuple(r.key() for r in problem.levels)
        if key != self._layout:
            levels = [r.level() for r in problem.levels]  # type: ignore[attr-defined]
            laid = StackProblem(levels, problem.lower, problem.upper, problem.scale, {})
            self._arena, self._layout = ProblemArena(laid), key
        else:
            self._arena.fill(problem)
        compiled_hqp.run(self.qp, self._arena, self.qp.workspace(self._arena))
        self._solves += 1
        out = self._arena.view(lay.I_OUT)
        return self._arena.view(lay.F_U)[1].copy(), SolverStatus(int(out[lay.OUT_STATUS]))

    def solution(self) -> SolverResult:
        """The last cascade's full outcome (levels, each task's residual, unmet tasks)."""
        if self._arena is None:
            raise SolverError("DynamicsSolver: nothing solved yet")
        return self.qp.result(self._arena, 0.0)

    def _checked(
        self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        if stack.robot is not self.robot:
            raise ConfigError("DynamicsSolver: the stack is over another robot")
        if any(isinstance(c, AccelerationLimits) for c in stack.constraints):
            raise ConfigError(
                "DynamicsSolver: the stack has AccelerationLimits; the torque level bounds "
                "the accelerations itself (DynamicsSolver(acceleration_limits=True)): leave "
                "them out of the stack"
            )
        q, u = np.asarray(q, dtype=float), np.asarray(u, dtype=float)
        if q.shape != (self.robot.nq,) or u.shape != (self.robot.nu,):
            raise DimensionError(
                f"DynamicsSolver: q must be ({self.robot.nq},) and u ({self.robot.nu},), got "
                f"{q.shape} and {u.shape}"
            )
        if not (np.isfinite(q).all() and np.isfinite(u).all()):
            raise DimensionError("DynamicsSolver: q and u must be finite")
        if not (math.isfinite(dt) and dt > 0.0):
            raise DimensionError(f"DynamicsSolver: dt must be positive, got {dt}")
        return q, u

    def _task_drifts(self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float) -> list | None:
        """Per level of the stack, its equality and inequality rows times ``u`` at
        ``q (+) eps u`` (``eps`` such that no coordinate moves more than ``DRIFT_STEP``), the
        first half of :meth:`_drift_rows`'s forward difference; None at rest."""
        speed = float(np.abs(u).max(initial=0.0))
        if speed == 0.0:
            return None
        self._eps = DRIFT_STEP / speed
        state = self.robot.update(self.robot.integrate(q, u, self._eps))
        problem = stack.evaluate(state, dt)
        u_s = u / problem.scale
        return [(lp.A @ u_s, lp.C @ u_s) for lp in problem.levels]

    def _drift_rows(self, problem: StackProblem, u: np.ndarray, ahead: list | None) -> list:
        """Per level, ``Jdot u`` of its equality and inequality rows: the forward difference
        ``(J(q (+) eps u) u - J(q) u) / eps`` (None per level at rest)."""
        if ahead is None:
            return [None] * len(problem.levels)
        u_s = u / problem.scale
        return [
            ((Au - lp.A @ u_s) / self._eps, (Cu - lp.C @ u_s) / self._eps)
            for (Au, Cu), lp in zip(ahead, problem.levels, strict=True)
        ]

    def _physics(self, q: np.ndarray, v: np.ndarray) -> _Physics:
        model, data = self.robot.model, self._data
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        contacts = [c.rows(model, data) for c in self.contacts]
        grasps = [o.rows(model, data) for o in self.objects]
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        M[np.diag_indices_from(M)] += self.rotor_inertia
        h = pin.nonLinearEffects(model, data, q, v) + self.friction * v
        return _Physics(M, h, contacts, grasps)

    def _task_levels(
        self, problem: StackProblem, u: np.ndarray, drifts: list, dt: float
    ) -> list[Rows]:
        """The stack's levels in acceleration form, over ``a`` (their columns unscaled)."""
        D, kd = problem.scale, self.velocity_gain
        u_s = u / D
        out = []
        last, self._last_b = self._last_b, [lp.b.copy() for lp in problem.levels]
        if last is not None and [b.shape for b in last] != [b.shape for b in self._last_b]:
            last = None  # (the stack's shape changed: no rate this step)
        for k, (lp, drift) in enumerate(zip(problem.levels, drifts, strict=True)):
            A = lp.A / D
            b = kd * (lp.b - lp.A @ u_s)
            if self.feedforward and last is not None:
                b += (lp.b - last[k]) / dt
            Cu = lp.C @ u_s
            lower, upper = (lp.lower - Cu) / dt, (lp.upper - Cu) / dt
            if drift is not None:
                b -= drift[0]
                lower, upper = lower - drift[1], upper - drift[1]
            out.append(
                Rows(
                    lp.name,
                    A,
                    b,
                    lp.C / D,
                    lower,
                    upper,
                    dict(lp.task_rows),
                    dict(lp.inequality_rows),
                    0.0,
                    None if lp.unweight is None else lp.unweight.copy(),
                    lp.reference_scale,
                )
            )
        return out if self.mode == "strict" else [self._weighted(out)]

    def _weighted(self, levels: list[Rows]) -> Rows:
        """The stack's levels as one: level ``k``'s rows times ``level_weights[k]``."""
        weights = self.level_weights or [1.0] * len(levels)
        if len(weights) != len(levels):
            raise ConfigError(
                f"DynamicsSolver: {len(weights)} level_weights for {len(levels)} levels"
            )
        rows, irows, k, m = {}, {}, 0, 0
        for lp in levels:
            for name, sl in lp.task_rows.items():
                key = f"{OBJECTIVES} ({lp.name})" if name == OBJECTIVES else name
                rows[key] = slice(k + sl.start, k + sl.stop)
            for name, sl in lp.inequality_rows.items():
                irows[name] = slice(m + sl.start, m + sl.stop)
            k, m = k + lp.A.shape[0], m + lp.C.shape[0]
        w = np.concatenate(
            [np.full(lp.A.shape[0], wk) for lp, wk in zip(levels, weights, strict=True)]
        )
        unweight = np.concatenate(
            [np.ones(lp.A.shape[0]) if lp.unweight is None else lp.unweight for lp in levels]
        )
        return Rows(
            "tasks",
            np.vstack([lp.A for lp in levels]) * w[:, None],
            np.concatenate([lp.b for lp in levels]) * w,
            np.vstack([lp.C for lp in levels]),
            np.concatenate([lp.lower for lp in levels]),
            np.concatenate([lp.upper for lp in levels]),
            rows,
            irows,
            0.0,
            unweight / np.where(w > 0, w, 1.0),
        )

    def _box(
        self, problem: StackProblem, q: np.ndarray, u: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on ``a``: the stack's box on the next velocity, and braking."""
        D = problem.scale
        lo, hi = (D * problem.lower - u) / dt, (D * problem.upper - u) / dt
        s = self._limited
        lower, upper = self.robot.position_limits
        b_lo, b_hi = braking_bounds(
            self.robot.joint_positions(q)[s], u[s], lower[s], upper[s], dt, self.braking
        )
        lo[s], hi[s] = np.maximum(lo[s], b_lo), np.minimum(hi[s], b_hi)
        if self.acceleration_limits:
            amax = self.robot.acceleration_limits
            lo, hi = np.maximum(lo, -amax), np.minimum(hi, amax)
        crossed = lo > hi
        lo[crossed] = hi[crossed] = 0.5 * (lo[crossed] + hi[crossed])
        # a floating base moves as the contacts and the joints make it: no bound of its own
        lo[self._unactuated], hi[self._unactuated] = -np.inf, np.inf
        return lo, hi

    def _cascade(
        self, physics: _Physics, levels: list[Rows], box: tuple[np.ndarray, np.ndarray]
    ) -> StackProblem:
        """The whole problem over ``x~ = [a, f / (m g)]``."""
        nu, fs = self.robot.nu, self.force_scale
        nf = self._wrench_count()
        n = nu + nf
        MA = physics.M @ self._A
        Jc = np.vstack(physics.jacobians()) if nf else np.zeros((0, MA.shape[0]))
        top: list[Rows] = []
        if self._unactuated.size:
            S = self._A[:, self._unactuated].T
            A0 = np.hstack([S @ MA, -S @ Jc.T * fs]) / fs
            b0 = -(S @ physics.h) / fs
            top.append(equality_level("equations of motion", A0, b0, n))
        top.append(self._contact_level(physics, MA, Jc, n))
        targets = self._wrench_targets(n)
        if targets is not None:
            top.append(targets)
        below = [padded(lp, n) for lp in levels]
        if nf:
            quiet = self._quiet_level(n)
            internal = self._internal(physics, n)
            below = [with_rows(lp, internal, self.wrench_regularization) for lp in below]
            below.append(quiet)
        lower = np.r_[box[0], np.full(nf, -np.inf)]
        upper = np.r_[box[1], np.full(nf, np.inf)]
        scale = np.r_[np.ones(nu), np.full(nf, fs)]
        return StackProblem(top + below, lower, upper, scale, {})

    def _contact_level(self, physics: _Physics, MA: np.ndarray, Jc: np.ndarray, n: int) -> Rows:
        """Contacts' acceleration rows; their wrench rows and the torque limits as
        inequalities."""
        nu, fs = self.robot.nu, self.force_scale
        A_rows, b_rows, names = [], [], {}
        C_rows, lo_rows, hi_rows, inames = [], [], [], {}
        col, row, irow = nu, 0, 0
        for contact, rows in zip(self.contacts, physics.contacts, strict=True):
            k = contact.size
            A = np.zeros((k, n))
            A[:, :nu] = rows.jacobian @ self._A
            A_rows.append(A)
            b_rows.append(rows.desired - rows.drift)
            names[f"contact {contact.frame}"] = slice(row, row + k)
            C = np.zeros((rows.C.shape[0], n))
            C[:, col : col + k] = rows.C * fs
            C_rows.append(C)
            lo_rows.append(rows.lower)
            hi_rows.append(rows.upper)
            inames[f"wrench {contact.frame}"] = slice(irow, irow + C.shape[0])
            col, row, irow = col + k, row + k, irow + C.shape[0]
        for obj, g in zip(self.objects, physics.grasps, strict=True):
            eq, b, ineq = self._grasp_rows(obj, g, col, n)
            for name, rows_ in eq.items():
                names[name] = slice(row, row + rows_.shape[0])
                A_rows.append(rows_)
                row += rows_.shape[0]
            b_rows += b
            if ineq.shape[0]:
                C_rows.append(ineq)
                lo_rows.append(np.full(ineq.shape[0], -np.inf))
                hi_rows.append(np.zeros(ineq.shape[0]))
                inames[f"grasp {obj.name}"] = slice(irow, irow + ineq.shape[0])
                irow += ineq.shape[0]
            col += obj.size
        d, At = self._driven, self._A.T
        T = np.hstack([At[d] @ MA, -(At[d] @ Jc.T) * fs])  # tau = A^T (M A a + h - Jc^T f)
        C_rows.append(T)
        h = At[d] @ physics.h
        lo_rows.append(-self.effort[d] - h)
        hi_rows.append(self.effort[d] - h)
        inames["torque limits"] = slice(irow, irow + d.size)
        # rows of unit norm: the cascade's tolerances are then the same for every row
        C = np.vstack(C_rows)
        norm = np.linalg.norm(C, axis=1)
        norm[norm == 0.0] = 1.0
        return Rows(
            "contacts and actuators",
            np.vstack(A_rows) if A_rows else np.zeros((0, n)),
            np.concatenate(b_rows) if b_rows else np.zeros(0),
            C / norm[:, None],
            np.concatenate(lo_rows) / norm,
            np.concatenate(hi_rows) / norm,
            names,
            inames,
        )

    def _wrench_targets(self, n: int) -> Rows | None:
        """The contacts' wrench targets (force tasks) as one level, or None without any:
        ``f_i = target_i`` (N, N m, scaled by the robot's weight) for each entry set."""
        rows, b, names, col = [], [], {}, self.robot.nu
        for c in self.contacts:
            if c.wrench_target is not None:
                held = np.flatnonzero(np.isfinite(c.wrench_target))
                block = np.zeros((held.size, n))
                block[np.arange(held.size), col + held] = 1.0
                names[f"wrench target {c.frame}"] = slice(len(b), len(b) + held.size)
                rows.append(block)
                b += list(c.wrench_target[held] / self.force_scale)
            col += c.size
        if not rows:
            return None
        A, empty = np.vstack(rows), np.zeros(0)
        return Rows("wrench targets", A, np.array(b), np.zeros((0, n)), empty, empty, names, {})

    def _quiet(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows the last level keeps small, over every wrench's columns (block diagonal:
        each contact's :meth:`~wholebody.dynamics.contacts.Contact.quiet` rows ``R``, a
        carried object's hands' whole wrenches), and for the contacts the metric
        ``W = R^T R + eps I``'s inverse and Cholesky factor (transposed): constant for a set
        of contacts and objects, made once per set."""
        key = tuple(map(id, self.contacts)) + tuple(map(id, self.objects))
        if key != self._quiet_key:
            R = [c.quiet() for c in self.contacts]
            k = sum(r.shape[1] for r in R)
            Rc = scipy.linalg.block_diag(*R) if R else np.zeros((0, 0))
            W = Rc.T @ Rc + 1e-6 * np.eye(k)
            rows = scipy.linalg.block_diag(Rc, *(np.eye(o.size) for o in self.objects))
            self._quiet_cache = (rows, np.linalg.inv(W), np.linalg.cholesky(W).T)
            self._quiet_key = key
        return self._quiet_cache

    def _quiet_level(self, n: int) -> Rows:
        """The last level: the contacts' tangential forces and torques small (in units of the
        robot's weight), where the levels above leave the wrenches free."""
        rows = self._quiet()[0]
        A = np.zeros((rows.shape[0], n))
        A[:, self.robot.nu :] = rows
        return equality_level("contact wrenches", A, np.zeros(A.shape[0]), n)

    def _internal(self, physics: _Physics, n: int) -> Rows:
        """Rows that keep the wrenches' internal part small: the part whose sum about the
        world's origin is zero (it pushes the contacts against each other; the motion never
        needs it), measured in the metric ``W`` of :meth:`_quiet`'s rows: ``f`` then tends
        to the quietest wrenches that make its sum (the load shared between the contacts,
        their centres of pressure central). A carried object's hands: the part of their
        wrenches that does not move it, in the plain metric."""
        _, W_inv, L_t = self._quiet()
        blocks = []
        if physics.contacts:
            G = np.hstack([c.to_world for c in physics.contacts])
            WG = W_inv @ G.T
            P = np.eye(G.shape[1]) - WG @ np.linalg.pinv(G @ WG) @ G  # (G may lack rank)
            blocks.append(L_t @ P)
        for g in physics.grasps:  # an object's hands: their sum moves it
            blocks.append(np.eye(g.E_f.shape[1]) - np.linalg.pinv(g.E_f) @ g.E_f)
        B = scipy.linalg.block_diag(*blocks)
        A = np.zeros((B.shape[0], n))
        A[:, self.robot.nu :] = B
        empty = np.zeros(0)
        rows = {"internal wrenches": slice(0, A.shape[0])}
        return Rows(
            "internal wrenches", A, np.zeros(A.shape[0]), np.zeros((0, n)), empty, empty, rows, {}
        )

    def _result(self, physics: _Physics, x: np.ndarray, status: SolverStatus) -> DynamicsResult:
        nu = self.robot.nu
        a, f = x[:nu].copy(), x[nu:].copy()
        dv = self._A @ a
        Q = physics.M @ dv + physics.h
        wrenches, col = {}, 0
        violations = {}
        for contact, rows in zip(self.contacts, physics.contacts, strict=True):
            w = f[col : col + contact.size]
            Q -= rows.jacobian.T @ w
            wrenches[contact.frame] = w
            Cw = rows.C @ w
            excess = np.maximum(rows.lower - Cw, Cw - rows.upper)
            violations[f"wrench {contact.frame}"] = max(float(excess.max(initial=0.0)), 0.0)
            col += contact.size
        squeeze = {}
        for obj, g in zip(self.objects, physics.grasps, strict=True):
            w = f[col : col + obj.size]
            Q -= np.vstack(g.jacobians).T @ w
            for i, hand in enumerate(obj.hands):
                wrenches[f"{obj.name}/{hand}"] = w[6 * i : 6 * i + 6]
            squeeze[obj.name] = float(g.squeeze @ w)
            excess = g.C @ w
            violations[f"grasp {obj.name}"] = max(float(excess.max(initial=0.0)), 0.0)
            col += obj.size
        d, tau = self._driven, self._A.T @ Q
        violations["torque limits"] = max(
            float((np.abs(tau[d]) - self.effort[d]).max(initial=0.0)), 0.0
        )
        violations["equations of motion"] = float(
            np.abs(Q[self._A[:, self._unactuated].any(axis=1)]).max(initial=0.0)
        )
        status = _status(status, max(violations.values(), default=0.0) > self.tolerance)
        return DynamicsResult(
            a, dv, Q, tau, wrenches, violations, status, self, self._solves, squeeze
        )


def _status(cascade: SolverStatus, exceeded: bool) -> SolverStatus:
    """A torque-level step's status: INFEASIBLE when a bound is exceeded (the physics cannot
    do what the contacts, torques and equations of motion ask), FAILED when the cascade
    failed, BOUNDS_ACTIVE when a task gave way to a bound (the unmet tasks are in
    :attr:`DynamicsResult.solution`), else the cascade's."""
    if exceeded:
        return SolverStatus.INFEASIBLE
    if cascade == SolverStatus.INFEASIBLE:
        return SolverStatus.BOUNDS_ACTIVE
    return cascade


def _actuator_limits(A: np.ndarray, effort: np.ndarray) -> np.ndarray:
    """The torque limit of each entry of ``u`` from those of the model's velocities: the
    limit of the velocity an entry drives itself (the last nonzero row of its column of
    ``A``: a joint's own, a wheel's own joint; a planar base's own root velocity)."""
    own = A.shape[0] - 1 - np.argmax(A[::-1] != 0.0, axis=0)
    return effort[own]
