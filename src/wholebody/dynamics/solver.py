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
``q`` and ``q (+) eps u`` for every task, built-in or a user's, and so is each contact's
``Jdot_c v`` (``eps`` such that no coordinate moves more than :data:`DRIFT_STEP`; its error
is about 1e-8 relative, checked against Pinocchio's frame accelerations in the tests). An
inequality row ``l <= C u' <= h`` on the next velocity ``u' = u + a dt`` becomes ``(l - C
u)/dt <= C a <= (h - C u)/dt``; so does the stack's box (velocity limits, position limits
for one step), intersected with the braking bounds of the joint position limits
(:func:`wholebody.kernels.torque.braking`) and the robot's acceleration limits; a floating
base's six are left free (the contacts and the joints move them).

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
:class:`~wholebody.solvers.HierarchicalQPSolver`). ``mode="weighted"`` sums the stack's
levels into one, level ``k``'s rows times ``level_weights[k]``, and solves one QP with daqp,
as TSID does: the equations of motion, the contacts and the wrench targets held exactly, every
inequality row and bound held, the least squares of the tasks' rows plus the quiet rows times
``wrench_regularization``; where that QP is infeasible (the contacts cannot be held within
their cones and the torque limits), the cascade solves the same levels instead, the contacts
then held as closely as they can be. Each stack level's rows are divided by ``max(1, ||b||)``
(the same optimum), so that the cascade's tolerances, relative to a level's residual, stay
tight on the contact and torque rows every level inherits: they hold to about 1e-9 of the
robot's weight. Wrenches are scaled by the robot's weight ``m g`` inside the QP, so the final
minimum-norm choice weighs ``||a||^2`` against ``||f / (m g)||^2``.

The step (:meth:`DynamicsSolver.solve`): the stack's rows and the contacts' velocities at
``q (+) eps u`` (one kernel on the kernels' own kinematics, :func:`wholebody.kernels.torque.
ahead`, where every entry of the stack is compiled) and the stack's rows at ``q``;
Pinocchio's ``M`` and ``h`` (and a carried object's rows); the contacts' rows
(:mod:`wholebody.kernels.contacts`); then the kernels of :mod:`wholebody.kernels.torque`
write the problem into the cascade's arena and solve it (the weighted QP, first on the last
step's working set, or the cascade's kernel) and compute the torques and the bounds'
excesses.

Nothing saturates silently: after each solve :attr:`DynamicsResult.violations` holds, per
kind of bound, how far the answer exceeds it (torques in N m or N, wrench rows in N or N m,
the equations of motion in N m), and the status is INFEASIBLE, with the contact or the
torque named, when any exceeds ``tolerance``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence

import numpy as np
import pinocchio as pin

from wholebody.dynamics.carry import CarriedObject, GraspRows
from wholebody.dynamics.contacts import Contact
from wholebody.dynamics.layout import Layout
from wholebody.dynamics.result import DynamicsResult
from wholebody.errors import ConfigError, DimensionError, SolverError
from wholebody.kernels import contacts as contact_kernels
from wholebody.kernels import daqp, torque
from wholebody.kernels import layout as lay
from wholebody.robot import Frame, Robot, RobotState
from wholebody.robot.sim import effort_limits
from wholebody.solvers import compiled_hqp
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.solvers.plan import Plan, kinematics_buffers
from wholebody.solvers.result import SolverResult, SolverStatus
from wholebody.solvers.stack import Stack
from wholebody.tasks.limits import AccelerationLimits

__all__ = ["DynamicsResult", "DynamicsSolver"]

GRAVITY = 9.81
"""m/s^2, the scale of the wrenches inside the QP (the robot's weight)."""
DRIFT_STEP = 1e-8
"""rad or m: the largest coordinate change of the forward difference that gives ``Jdot u``."""


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
        ``"strict"`` (a strict hierarchy over the stack's levels) or ``"weighted"`` (one QP).
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
        level chooses them). In the weighted mode, also the weight of the quiet rows.
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
        self.level_weights = None if level_weights is None else [float(w) for w in level_weights]
        self.wrench_regularization = float(wrench_regularization)
        if not (math.isfinite(self.wrench_regularization) and self.wrench_regularization >= 0):
            raise ConfigError(
                f"DynamicsSolver: wrench_regularization must be >= 0, got {wrench_regularization}"
            )
        self.tolerance = _checked_gain("tolerance", tolerance)
        self._model_arrays(robot)
        self.qp = HierarchicalQPSolver(engine, bound_relaxation=1e-12, stall_damping=0.0)
        self._daqp = daqp.settings(primal_tol=1e-9, iter_limit=2000)  # (as the cascade's)
        self._layout: Layout | None = None
        self._stack: Stack | None = None
        self._last_b = np.zeros(0)
        self._solves, self._cascaded = 0, True
        self.state: RobotState | None = None
        """The kinematics at the last solve's ``q`` (valid until the robot's next update):
        what the stack's :meth:`~wholebody.solvers.Stack.advance` takes after the step."""
        self.contacts: list[Contact] = []
        self._pack_contacts()
        self.objects: list[CarriedObject] = []
        """The carried objects (:meth:`carry`, :mod:`wholebody.dynamics.carry`)."""
        for contact in contacts:
            self.add_contact(contact)

    def _model_arrays(self, robot: Robot) -> None:
        """The robot's constant numbers as the kernels take them."""
        model = robot.model
        self._data = model.createData()
        self._A = A = np.asarray(robot.actuation)
        kin = robot.kinematics
        self._act = (kin.act_k, kin.act_j, kin.act_a)  # A's non-zero entries
        root = A[:6] if robot.base.floating else A[:0]
        self.unactuated = np.flatnonzero(np.abs(root).sum(axis=0) > 0)
        """The entries of ``u`` that move a floating base (no motor: their rows of the
        equations of motion are equalities)."""
        self._eom_rows = np.flatnonzero(A[:, self.unactuated].any(axis=1))
        self.effort = _actuator_limits(A, effort_limits(robot, robot.sim_settings))
        """The torque limit of each entry of ``u`` (N m, N: a joint's, a wheel's; inf for a
        floating base's six, which have no motor)."""
        self.driven = np.setdiff1d(np.flatnonzero(np.isfinite(self.effort)), self.unactuated)
        """The entries of ``u`` whose torque is bounded (``effort``)."""
        lower, upper = robot.position_limits
        self._limits = np.vstack([lower, upper, robot.acceleration_limits])
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
        self._par = np.zeros(torque.P_WIDTH)
        self._zero_v = np.zeros(model.nv)
        kin, movable = kinematics_buffers(robot)
        self._kin = kin if movable else None  # (torque.ahead's, where they move the robot)

    def add_contact(self, contact: Contact) -> None:
        """Make ``contact`` active (its frame checked against the robot)."""
        if any(c.frame == contact.frame for c in self.contacts):
            raise ConfigError(f"DynamicsSolver: a contact on {contact.frame!r} is already active")
        if contact.size not in (contact_kernels.PATCH, contact_kernels.POINT):
            raise ConfigError(
                f"DynamicsSolver: a contact is a PatchContact or a PointContact, got "
                f"{type(contact).__name__}"
            )
        contact.bind(self.robot.model)
        self.contacts.append(contact)
        self._pack_contacts()

    def remove_contact(self, frame: str) -> Contact:
        """Break the contact on ``frame``; returns it."""
        for i, c in enumerate(self.contacts):
            if c.frame == frame:
                self.contacts.pop(i)
                self._pack_contacts()
                return c
        raise ConfigError(f"DynamicsSolver: no active contact on {frame!r}")

    def _pack_contacts(self) -> None:
        """The active contacts as the kernels of :mod:`wholebody.kernels.contacts` take
        them: their kinds and frames, the velocities that move them, their gains and
        references (written each step) and their velocities a moment ahead."""
        model, n = self.robot.model, len(self.contacts)
        table = [(c.size, c.frame_id) for c in self.contacts]
        self._contact_table = np.array(table, dtype=np.int64).reshape(n, contact_kernels.CT_WIDTH)
        frames = [
            Frame(c.frame, c.frame_id, model.frames[c.frame_id].parentJoint) for c in self.contacts
        ]
        self._support = self.robot.kinematics.support(frames)
        self._contact_par = np.zeros((n, contact_kernels.CP_WIDTH))
        self._twists = np.zeros((n, 6))

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

    @property
    def layout(self) -> Layout | None:
        """The last step's problem shape: its levels, the cascade's arena holding the
        problem, the kernels' buffers (:class:`~wholebody.dynamics.layout.Layout`)."""
        return self._layout

    @property
    def cascaded(self) -> bool:
        """Whether the cascade solved the last step (strict mode, or the weighted QP was
        infeasible)."""
        return self._cascaded

    def layout_key(self, plan: Plan) -> tuple:
        """What the problem's shape depends on: the stack's plan, the contacts, the carried
        objects, which wrench entries have targets, the mode and its weights."""
        targets = tuple(
            None if c.wrench_target is None else tuple(np.isfinite(c.wrench_target))
            for c in self.contacts
        )
        return (
            id(plan),
            tuple(map(id, self.contacts)),
            tuple(map(id, self.objects)),
            targets,
            self.mode,
            None if self.level_weights is None else tuple(self.level_weights),
            self.wrench_regularization > 0.0,
        )

    # ------------------------------------------------------------------ the step
    def solve(self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float) -> DynamicsResult:
        """The accelerations, torques and wrenches of one control step of ``dt`` seconds at
        the configuration ``q`` and actuated velocity ``u`` (rad/s, m/s)."""
        t0 = time.perf_counter()
        q, u = self._checked(stack, q, u, dt)
        v = self._A @ u
        plan, ahead = self._rows(stack, q, u, dt)
        grasps, M, h = self._physics(q, v)
        layout = self._layout
        if layout is None or layout.key != self.layout_key(plan):
            _no_acceleration_limits(stack)
            layout = self._layout = Layout(self, plan, grasps)
        self._contact_rows(layout, v)
        layout.fill(self, grasps)
        self._assemble(layout, plan, q, u, ahead, dt, M, h)
        t1 = time.perf_counter()
        x, status = self._run(layout)
        t2 = time.perf_counter()
        result = self._outcome(layout, x, status, M, h, grasps)
        result.solve_time, result.qp_time = time.perf_counter() - t0, t2 - t1
        return result

    def _checked(
        self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        if stack.robot is not self.robot:
            raise ConfigError("DynamicsSolver: the stack is over another robot")
        q, u = np.asarray(q, dtype=float), np.asarray(u, dtype=float)
        if q.shape != (self.robot.nq,) or u.shape != (self.robot.nu,):
            raise DimensionError(
                f"DynamicsSolver: q must be ({self.robot.nq},) and u ({self.robot.nu},), got "
                f"{q.shape} and {u.shape}"
            )
        finite = math.isfinite(q @ q + u @ u)  # (an overflow: the full check decides)
        if not (finite or (np.isfinite(q).all() and np.isfinite(u).all())):
            raise DimensionError("DynamicsSolver: q and u must be finite")
        if not (math.isfinite(dt) and dt > 0.0):
            raise DimensionError(f"DynamicsSolver: dt must be positive, got {dt}")
        if stack is not self._stack:  # another stack: its rows' rates start anew
            self._stack, self._last_b = stack, np.zeros(0)
        return q, u

    def _rows(
        self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float
    ) -> tuple[Plan, np.ndarray]:
        """The stack's plan evaluated at ``q``, and ``ahead``: its rows ``A u~`` and ``C u~``
        (K + P) evaluated at ``q (+) eps u``, ``eps`` such that no coordinate moves more than
        :data:`DRIFT_STEP` (the first half of the forward difference that gives ``Jdot u``;
        ``eps = 0`` and ``ahead`` unread at rest)."""
        speed = float(np.abs(u).max(initial=0.0))
        eps = DRIFT_STEP / speed if speed > 0.0 else 0.0
        self._par[torque.P_EPS] = eps
        ahead, ahead_plan = np.zeros(0), None
        for _ in range(2):  # (again where the plan was laid out anew between the two)
            if eps > 0.0:
                ahead_plan, ahead = self._ahead(stack, q, u, dt, eps)
            self.state = self.robot.update(q)
            plan = stack.evaluated_plan(self.state, dt)
            if eps == 0.0 or plan is ahead_plan:
                return plan, ahead
        raise SolverError(
            "DynamicsSolver: the stack was laid out anew between its two evaluations, twice "
            "(an entry whose rows change shape with the configuration?)"
        )

    def _ahead(
        self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float, eps: float
    ) -> tuple[Plan, np.ndarray]:
        """The plan and its rows times ``u~`` at ``q (+) eps u``, and the contacts' velocities
        there (:attr:`_twists`): by one kernel on the kernels' own kinematics
        (:func:`~wholebody.kernels.torque.ahead`) where every entry is compiled, else by
        Pinocchio's and the stack's Python entries."""
        plan = stack.plan()
        contacts = (self._contact_table, self._support, self._twists)
        if self._kin is not None and not plan.python:
            plan.sync(None, dt)
            if not plan.stale:
                out = np.empty(_row_count(plan))
                torque.ahead((plan.f, plan.i, plan.h), self._kin, contacts, q, u, eps, out)
                return plan, out
        plan = stack.evaluated_plan(self.robot.update(self.robot.integrate(q, u, eps)), dt)
        J, oMf = self.robot.kinematics.views()
        contact_kernels.twists(J, oMf, *contacts[:2], self._A @ u, self._twists)
        return plan, _rows_times(plan, u)

    def drifts(self, stack: Stack, q: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """``Jdot u`` (K + P) of the stack's equality rows and inequality rows at ``(q, u)``,
        in the units of the stack's evaluated rows (:meth:`~wholebody.solvers.Stack.evaluate`)
        per second: the forward difference the step uses (zeros at rest)."""
        q, u = self._checked(stack, q, u, dt)
        plan, ahead = self._rows(stack, q, u, dt)
        eps = self._par[torque.P_EPS]
        now = _rows_times(plan, u)
        return (ahead - now) / eps if eps > 0.0 else np.zeros(now.size)

    def _physics(
        self, q: np.ndarray, v: np.ndarray
    ) -> tuple[list[GraspRows], np.ndarray, np.ndarray]:
        """Each carried object's rows, and Pinocchio's ``M`` (its upper triangle) and ``h``
        at ``(q, v)``: :func:`~wholebody.kernels.torque.assemble` makes ``M`` symmetric and
        adds the drives' rotor inertia and friction, in place."""
        model, data = self.robot.model, self._data
        grasps = []
        if self.objects:
            pin.forwardKinematics(model, data, q, v, self._zero_v)
            pin.updateFramePlacements(model, data)
            pin.computeJointJacobians(model, data)  # (on forwardKinematics' placements)
            grasps = [o.rows(model, data) for o in self.objects]
        M = pin.crba(model, data, q)  # (upper triangle; the kernel adds the drives)
        return grasps, M, pin.nonLinearEffects(model, data, q, v)

    def _contact_rows(self, layout: Layout, v: np.ndarray) -> None:
        """The contacts' rows at the state of the robot's kinematics (the step's ``q``) into
        the layout's buffers (:func:`wholebody.kernels.contacts.contact_rows`)."""
        for k, c in enumerate(self.contacts):
            c.pack(self._contact_par[k])
        J, oMf = self.robot.kinematics.views()
        contact_kernels.contact_rows(
            J,
            oMf,
            self._contact_table,
            self._support,
            self._contact_par,
            v,
            self._twists,
            self._par[torque.P_EPS],
            (layout.Jw, layout.eq_dv, layout.eq_b, layout.G),
        )

    def _assemble(
        self,
        layout: Layout,
        plan: Plan,
        q: np.ndarray,
        u: np.ndarray,
        ahead: np.ndarray,
        dt: float,
        M: np.ndarray,
        h: np.ndarray,
    ) -> None:
        """The step's problem into the layout's arena (:func:`wholebody.kernels.torque.
        assemble`)."""
        b = plan.view(lay.F_B)
        par = self._par
        par[torque.P_DT], par[torque.P_KD] = dt, self.velocity_gain
        par[torque.P_FS], par[torque.P_BRAKING] = self.force_scale, self.braking
        par[torque.P_REGULARIZATION] = self.wrench_regularization
        par[torque.P_FEEDFORWARD] = float(self.feedforward and self._last_b.size == b.size)
        par[torque.P_ACCELERATION] = float(self.acceleration_limits)
        arena = layout.arena
        torque.assemble(
            (arena.f, arena.i, arena.h),
            layout.spec,
            (plan.f, plan.i, plan.h),
            par,
            (u, self.robot.joint_positions(q), ahead, self._last_b, layout.level_weights),
            (self._act, self.driven, self.effort, self.unactuated, self._limits),
            (M, h, layout.Jw, self.rotor_inertia, self.friction),
            (layout.eq_dv, layout.eq_f, layout.eq_b, layout.cf, layout.cf_lo, layout.cf_hi),
            (
                layout.targets,
                layout.target_b,
                layout.internal,
                layout.quiet,
                layout.G,
                layout.W_inv,
                layout.L_t,
            ),
        )
        self._last_b = b.copy()

    def _run(self, layout: Layout) -> tuple[np.ndarray, SolverStatus]:
        """The answer ``[a, f]`` and its status: the weighted mode's QP where it is
        feasible, else the cascade's kernel."""
        arena = layout.arena
        self._solves += 1
        if self.mode == "weighted":
            x = np.empty(layout.n)
            flag, bounded = torque.weighted_qp(
                (arena.f, arena.i, arena.h),
                layout.spec,
                layout.hard,
                self.wrench_regularization,
                layout.deferred,
                self._daqp,
                layout.active,
                x,
            )
            if flag > 0:
                self._cascaded = False
                x *= arena.view(lay.F_METRIC)[0]
                return x, SolverStatus.BOUNDS_ACTIVE if bounded else SolverStatus.OK
        self._cascade(layout)
        out = arena.view(lay.I_OUT)
        return arena.view(lay.F_U)[1].copy(), SolverStatus(int(out[lay.OUT_STATUS]))

    def _cascade(self, layout: Layout) -> None:
        compiled_hqp.run(self.qp, layout.arena, self.qp.workspace(layout.arena))
        self._cascaded = True

    def solution(self) -> SolverResult:
        """The last step's problem solved by the cascade (levels, each task's residual,
        unmet tasks): in the weighted mode, solved again by it now (the same optimum where
        the weighted QP was feasible)."""
        if self._layout is None or not self._solves:
            raise SolverError("DynamicsSolver: nothing solved yet")
        if not self._cascaded:
            self._cascade(self._layout)
        return self.qp.result(self._layout.arena, 0.0)

    def _outcome(
        self,
        layout: Layout,
        x: np.ndarray,
        status: SolverStatus,
        M: np.ndarray,
        h: np.ndarray,
        grasps: list[GraspRows],
    ) -> DynamicsResult:
        """The result: torques, wrenches, squeezes and the bounds' excesses of ``x``."""
        nu, nv = self.robot.nu, self.robot.model.nv
        dv, Q, tau = np.empty(nv), np.empty(nv), np.empty(nu)
        excess = np.empty(len(self.contacts) + len(self.objects) + 2)
        torque.outcome(
            x,
            (self._act, self.driven, self.effort, self._eom_rows, self.force_scale),
            (M, h, layout.Jw),
            layout.cf,
            layout.cf_lo,
            layout.cf_hi,
            layout.owner,
            (dv, Q, tau, excess),
        )
        a, f = x[:nu].copy(), x[nu:]
        wrenches, violations, squeeze, col = {}, {}, {}, 0
        for k, c in enumerate(self.contacts):
            wrenches[c.frame] = f[col : col + c.size].copy()
            violations[f"wrench {c.frame}"] = float(excess[k])
            col += c.size
        for k, (o, g) in enumerate(zip(self.objects, grasps, strict=True)):
            w = f[col : col + o.size]
            for i, hand in enumerate(o.hands):
                wrenches[f"{o.name}/{hand}"] = w[6 * i : 6 * i + 6].copy()
            squeeze[o.name] = float(g.squeeze @ w)
            violations[f"grasp {o.name}"] = float(excess[len(self.contacts) + k])
            col += o.size
        violations["torque limits"] = float(excess[-2])
        violations["equations of motion"] = float(excess[-1])
        status = _status(status, max(violations.values()) > self.tolerance)
        return DynamicsResult(
            a, dv, Q, tau, wrenches, violations, status, self, self._solves, squeeze
        )


def _no_acceleration_limits(stack: Stack) -> None:
    """ConfigError where ``stack`` has :class:`~wholebody.tasks.AccelerationLimits` (checked
    whenever the problem is laid out: a stack's constraints are fixed with its plan)."""
    if any(isinstance(c, AccelerationLimits) for c in stack.constraints):
        raise ConfigError(
            "DynamicsSolver: the stack has AccelerationLimits; the torque level bounds "
            "the accelerations itself (DynamicsSolver(acceleration_limits=True)): leave "
            "them out of the stack"
        )


def _row_count(plan: Plan) -> int:
    """K + P: the plan's equality and inequality rows."""
    return plan.view(lay.F_A).shape[0] + plan.view(lay.F_C).shape[0]


def _rows_times(plan: Plan, u: np.ndarray) -> np.ndarray:
    """The plan's evaluated rows times ``u~ = u / D``: ``[A u~, C u~]`` (K + P;
    :func:`~wholebody.kernels.torque.rows_times`)."""
    out = np.empty(_row_count(plan))
    torque.rows_times((plan.f, plan.i, plan.h), u, out)
    return out


def _status(solved: SolverStatus, exceeded: bool) -> SolverStatus:
    """A torque-level step's status: INFEASIBLE when a bound is exceeded (the physics cannot
    do what the contacts, torques and equations of motion ask), FAILED when the solve
    failed, BOUNDS_ACTIVE when a task gave way to a bound (the cascade's unmet tasks are in
    :attr:`DynamicsResult.solution`), else OK."""
    if exceeded:
        return SolverStatus.INFEASIBLE
    if solved == SolverStatus.INFEASIBLE:
        return SolverStatus.BOUNDS_ACTIVE
    return solved


def _actuator_limits(A: np.ndarray, effort: np.ndarray) -> np.ndarray:
    """The torque limit of each entry of ``u`` from those of the model's velocities: the
    limit of the velocity an entry drives itself (the last nonzero row of its column of
    ``A``: a joint's own, a wheel's own joint; a planar base's own root velocity)."""
    own = A.shape[0] - 1 - np.argmax(A[::-1] != 0.0, axis=0)
    return effort[own]
