"""MuJoCo physics in the control loop: the controller's velocities through joint servos.

Each control period the controller commands actuated velocities ``u``; the plant turns them
into model velocities ``v = A u`` (a planar base's twist rotated into the world by the
simulated yaw at every physics step; a floating base's six are not driven, the contacts and
the joints carry it) and runs ``dt / timestep`` physics steps in which every
degree of freedom of the robot follows its velocity through a **PI velocity servo with the
robot's inertia** (an inverse-dynamics joint servo, as a torque-controlled robot runs it)::

    tau = M(q) (kv (v - qd) + kp s) + b(q, qd),      s' = v - qd   (the setpoint lag)

with ``kv = 2 zeta w``, ``kp = w^2`` (``w = 2 pi servo_hz``): every joint answers like a
critically damped second-order system of bandwidth ``servo_hz`` whatever the posture (gains
on the joint's own inertia alone went unstable where two axes align and the inertia a joint
sees collapses). Each torque is clamped at the joint's limit, a wheeled base's force so that
no wheel exceeds its own (``s`` stops growing while clamped and never asks more than the
limit at the start posture's inertia); ``b`` is the robot's gravity and Coriolis torque from
the model when ``gravity_compensation``, less, under a floating base, the generalised force
of the contacts at the last physics step (``J_c^T f_c``: the floor carries the robot through
its legs, as the ankles' force sensors tell a torque-controlled humanoid). A floating base's
own six have no servo and no torque: its acceleration in ``M(q) acc`` is taken as 0. ``M``
and ``b`` are the robot's own: a carried object's weight and the grasp's forces are not in
them, the servo's lag holds them. Velocity
commands are ramped over the period from the last one (first-order hold), as a drive
interpolates its setpoints. The controller then reads the simulated configuration, not its
own integration: as it is, or through a ``sensor``
(:class:`~wholebody.control.sensor.JointSensor`: noise on the encoders, a delay of whole
control periods).

Per control period the plant records the applied torque's peak, the joints that saturated,
every grasp's force on its object, the contacts and the free objects' poses
(:class:`PhysicsLog`). A joint
held at its limit for ``stall_time`` sets :attr:`MujocoPlant.stop_reason`, which ends the
run with the joint, the torque it asked for and its limit, rather than letting it diverge.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from wholebody.control.sensor import JointSensor
from wholebody.errors import DimensionError, ModelError
from wholebody.robot import Robot
from wholebody.robot.sim import SimSettings, wheel_dofs
from wholebody.sim.world import World, build_world

if TYPE_CHECKING:
    from wholebody.scenarios.spec import ObjectSpec

__all__ = ["MujocoPlant", "PhysicsLog"]


@dataclass
class PhysicsLog:
    """Per control period (rows), in the robot's velocity order (Pinocchio ``nv``; a planar
    root's three are world x, y, yaw; a free flyer's six have no torque, always 0).

    Attributes
    ----------
    torque_peak
        (N, nv) peak absolute applied torque over the period's physics steps (N m, N).
    saturated
        (N, nv) whether the joint was at its limit in the period.
    wheel_torque_peak
        (N, wheels) peak absolute wheel torque that gives the planar base's force (N m, ``B^T W``;
        empty without wheels). The wheels' own joints only spin in the model.
    grasp_force
        ``(object, hand frame)`` -> (N, 3) force of that grasp on the object at the
        period's end (N, world; zero while not grasping).
    object_poses
        Free object -> (N, 4, 4) pose at the start of the period (world).
    configuration
        (N, nq) the simulated configuration at the start of the period (Pinocchio's ``q``):
        the robot's true state, which the controller saw unless a sensor perturbs or delays
        it.
    contacts
        ``"shape|object"`` -> ``[first time (s), peak normal force (N)]`` of every contact of
        a robot shape with a fixed object (free objects do not touch the robot) and of a
        held object with anything, sampled at the periods' ends.
    """

    torque_peak: list[np.ndarray] = field(default_factory=list)
    saturated: list[np.ndarray] = field(default_factory=list)
    wheel_torque_peak: list[np.ndarray] = field(default_factory=list)
    grasp_force: dict[tuple[str, str], list[np.ndarray]] = field(default_factory=dict)
    object_poses: dict[str, list[np.ndarray]] = field(default_factory=dict)
    contacts: dict[str, list[float]] = field(default_factory=dict)
    configuration: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> dict[str, object]:
        """The records as arrays."""
        return {
            "torque_peak": np.array(self.torque_peak),
            "saturated": np.array(self.saturated),
            "wheel_torque_peak": np.array(self.wheel_torque_peak),
            "grasp_force": {k: np.array(v) for k, v in self.grasp_force.items()},
            "object_poses": {k: np.array(v) for k, v in self.object_poses.items()},
            "contacts": {k: list(v) for k, v in self.contacts.items()},
            "configuration": np.array(self.configuration),
        }


class MujocoPlant:
    """A robot and objects in MuJoCo, stepped by a controller's velocity commands.

    ``plant.step(q, u, dt)`` has the signature of :meth:`Robot.integrate` (``q`` is
    ignored: the state is the simulator's) and returns the simulated configuration; give the
    plant to :class:`~wholebody.control.Controller` (``plant=``). ``grasps``: the
    ``(object, hand frame)`` pairs that may be welded (:meth:`hold`). ``sensor``: what the
    returned configuration is (:class:`~wholebody.control.sensor.JointSensor`; default the
    simulated one, exactly); :attr:`PhysicsLog.configuration` keeps the true one.
    """

    def __init__(
        self,
        robot: Robot,
        objects: Iterable[ObjectSpec] = (),
        grasps: Iterable[tuple[str, str]] = (),
        settings: SimSettings | None = None,
        sensor: JointSensor | None = None,
    ) -> None:
        self.robot = robot
        self.settings = settings or SimSettings()
        self.sensor = sensor or JointSensor()
        if not isinstance(self.sensor, JointSensor):
            raise ModelError(f"sensor must be a wholebody.control.JointSensor, got {sensor!r}")
        self.world: World = build_world(robot, objects, grasps, self.settings)
        self.model = self.world.model
        self.data = mujoco.MjData(self.model)
        self._maps()
        self.stop_reason: str | None = None
        self.log = PhysicsLog()
        self.reset(robot.neutral())

    # ------------------------------------------------------------------ configuration maps
    def _maps(self) -> None:
        """Index arrays between Pinocchio's ``q`` and MuJoCo's ``qpos``."""
        model, m = self.robot.model, self.model
        scalar, cont, planar, free = [], [], [], []
        for i, names in self.world.joints.items():
            j = model.joints[i]
            adr = [int(m.jnt_qposadr[m.joint(n).id]) for n in names]
            if j.nq == 7:  # a free flyer: (x, y, z, qx, qy, qz, qw), MuJoCo's (.., qw, ..)
                free.append((j.idx_q, adr[0]))
            elif len(names) == 3:
                planar.append((j.idx_q, *adr))
            elif j.nq == 2:
                cont.append((j.idx_q, adr[0]))
            else:
                scalar.append((j.idx_q, adr[0]))
        self._scalar = np.array(scalar, dtype=int).reshape(-1, 2)
        self._cont = np.array(cont, dtype=int).reshape(-1, 2)
        self._planar = planar[0] if planar else None
        self._free = free[0] if free else None
        self.planar = bool(planar)
        """Whether the robot's root is a planar base (its first three velocities: world x,
        y, yaw)."""
        self._dofs = self.world.dofs
        # the velocities with a motor: all but a free flyer's six
        self._driven = np.arange(6 if free else 0, self.robot.nv)
        self._actuators = np.array(
            [m.actuator(m.joint(m.dof_jntid[d]).name).id for d in self._dofs[self._driven]],
            dtype=int,
        )
        self._A = np.asarray(self.robot.actuation)
        base = self.robot.base
        self._wheels = base.matrix if (planar and base.wheel_joints) else np.zeros((3, 0))
        self._wheel_v = np.array(wheel_dofs(self.robot), dtype=int)

    def qpos(self, q: np.ndarray) -> np.ndarray:
        """MuJoCo's robot positions of a Pinocchio configuration (objects untouched)."""
        qpos = self.data.qpos.copy()
        s, c = self._scalar, self._cont
        qpos[s[:, 1]] = q[s[:, 0]]
        qpos[c[:, 1]] = np.arctan2(q[c[:, 0] + 1], q[c[:, 0]])
        if self._planar is not None:
            iq, ax, ay, ayaw = self._planar
            qpos[[ax, ay]] = q[iq : iq + 2]
            qpos[ayaw] = np.arctan2(q[iq + 3], q[iq + 2])
        if self._free is not None:
            iq, a = self._free
            qpos[a : a + 3] = q[iq : iq + 3]
            qpos[a + 3 : a + 7] = q[iq + 6], q[iq + 3], q[iq + 4], q[iq + 5]
        return qpos

    def configuration(self) -> np.ndarray:
        """The simulated robot's Pinocchio configuration."""
        qpos, q = self.data.qpos, np.empty(self.robot.nq)
        s, c = self._scalar, self._cont
        q[s[:, 0]] = qpos[s[:, 1]]
        q[c[:, 0]], q[c[:, 0] + 1] = np.cos(qpos[c[:, 1]]), np.sin(qpos[c[:, 1]])
        if self._planar is not None:
            iq, ax, ay, ayaw = self._planar
            q[iq : iq + 4] = qpos[ax], qpos[ay], np.cos(qpos[ayaw]), np.sin(qpos[ayaw])
        if self._free is not None:
            iq, a = self._free
            w, x, y, z = qpos[a + 3 : a + 7] / np.linalg.norm(qpos[a + 3 : a + 7])
            q[iq : iq + 7] = *qpos[a : a + 3], x, y, z, w
        return q

    # ------------------------------------------------------------------ running
    def reset(self, q: np.ndarray) -> None:
        """Robot at ``q`` and at rest, objects where the model puts them, grasps off, the
        servos' anti-windup bound from the inertia at ``q``, the sensor's history at ``q``
        (and its noise's generator at its seed), the log emptied."""
        q = self.robot.check_configuration(q)
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = self.qpos(q)
        self.data.eq_active[:] = 0
        mujoco.mj_forward(self.model, self.data)
        w = 2 * np.pi * self.settings.servo_hz
        self.kp, self.kv = w * w, 2 * self.settings.damping_ratio * w
        M = np.empty((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, M)
        self._lag_bound = self.world.effort / (self.kp * np.diag(M)[self._dofs])
        self._acc, self._force = np.zeros(self.model.nv), np.zeros(self.model.nv)
        self.lag = np.zeros(self.robot.nv)
        self._command = np.zeros(self.robot.nv)
        self._stalled = np.zeros(self.robot.nv, dtype=int)
        self.stop_reason = None
        self.log = PhysicsLog()
        self.time = 0.0
        self._readout = self.sensor.start(self.robot, q)
        self._seen = q.copy()  # what the controller was last given

    def hold(self, grasps: Iterable[tuple[str, str]]) -> None:
        """Weld each ``(object, hand frame)`` of ``grasps`` where they are now (a weld on
        already stays as it is); every other grasp released."""
        grasps = set(grasps)
        mujoco.mj_kinematics(self.model, self.data)
        unknown = sorted(grasps - set(self.world.welds))
        if unknown:
            raise ModelError(
                f"no grasp {unknown[0]} in the model; its grasps: {list(self.world.welds)}"
            )
        for (name, frame), eq in self.world.welds.items():
            on = (name, frame) in grasps
            if on and not self.data.eq_active[eq]:
                gap = self._reach(frame, name)
                if gap > 0:
                    self.stop_reason = (
                        f"grasp of {name} failed at t = {self.time:.2f} s: "
                        f"{frame} is {gap * 1e3:.0f} mm out of reach"
                    )
                    on = False
                else:
                    self._weld_here(eq, self.world.hand_bodies[frame], self.world.objects[name])
            self.data.eq_active[eq] = int(on)

    def _reach(self, frame: str, name: str, margin: float = 0.05) -> float:
        """How far (m) the hand's frame is beyond the object's bounding sphere plus
        ``margin``: a grasp needs the hand at the object (0 or less)."""
        obj = self.world.objects[name]
        geom = int(self.model.body_geomadr[obj])
        hand = self.robot.frame_pose(self.configuration(), frame)[:3, 3]
        return float(
            np.linalg.norm(hand - self.data.xpos[obj]) - self.model.geom_rbound[geom] - margin
        )

    def _weld_here(self, eq: int, hand: int, obj: int) -> None:
        """The weld's relative pose set to the bodies' current one (no jump when it starts)."""
        d = self.data
        R_h, R_o = d.xmat[hand].reshape(3, 3), d.xmat[obj].reshape(3, 3)
        pos = R_h.T @ (d.xpos[obj] - d.xpos[hand])
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, (R_h.T @ R_o).ravel())
        self.model.eq_data[eq, :3] = 0.0  # anchor: the object's origin
        self.model.eq_data[eq, 3:6] = pos
        self.model.eq_data[eq, 6:10] = quat
        self.model.eq_data[eq, 10] = 1.0

    def step(self, q: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """Run the physics for ``dt`` (s) under the command ``u`` from ``q``, which must be
        the configuration the plant gave last (:meth:`reset` a plant to start elsewhere);
        the configuration reached, as the sensor reads it. If MuJoCo finds the state
        unusable (a NaN or a huge value: it then resets its data), the run stops there
        (:attr:`stop_reason`) and the configuration given before the step is returned."""
        now = self.configuration()
        n = self._periods(q, dt)
        v = self._A @ np.asarray(u, dtype=float)
        m, d = self.model, self.data
        self._record_poses()
        self.log.configuration.append(now)
        peak, demand = np.zeros(self.robot.nv), np.zeros(self.robot.nv)
        wheels = np.zeros(self._wheels.shape[1])
        saturated = np.zeros(self.robot.nv, dtype=bool)
        previous, self._command = self._command, v
        warnings = self._warnings()
        for i in range(n):
            mujoco.mj_step1(m, d)
            tau, asked, at_limit, wheel = self._servo(previous + (v - previous) * ((i + 1) / n))
            np.maximum(wheels, np.abs(wheel), out=wheels)
            d.ctrl[self._actuators] = tau[self._driven]
            np.maximum(peak, np.abs(tau), out=peak)
            np.maximum(demand, np.abs(asked), out=demand)
            saturated |= at_limit
            self._stalled = np.where(at_limit, self._stalled + 1, 0)
            mujoco.mj_step2(m, d)
        return self._finish(n, peak, saturated, wheels, demand, warnings)

    def body_of(self, frame: str) -> int:
        """The MuJoCo body that carries the robot frame ``frame`` (its parent joint's)."""
        model = self.robot.model
        if not model.existFrame(frame):
            raise ModelError(f"robot {self.robot.name!r} has no frame {frame!r}")
        joint = model.frames[model.getFrameId(frame)].parentJoint
        if joint == 0:
            return 0  # the world
        name = self.world.joints[joint][0]
        return int(self.model.jnt_bodyid[self.model.joint(name).id])

    def velocity(self) -> np.ndarray:
        """The simulated robot's Pinocchio velocity ``v`` (nv): a planar root's in the base
        frame, a free flyer's linear and angular velocity in its own frame (MuJoCo keeps the
        linear one in the world's); a wheeled base's wheels at the speeds that roll it as
        its root moves (in the simulation they only spin, nothing ties them to the floor)."""
        v = self.data.qvel[self._dofs].copy()
        if self._planar is not None:
            yaw = self.data.qpos[self._planar[3]]
            c, s = np.cos(yaw), np.sin(yaw)
            v[0], v[1] = c * v[0] + s * v[1], -s * v[0] + c * v[1]
        if self._wheels.size:  # the wheels' speeds that roll the base as it moves
            v[self._wheel_v] = np.linalg.lstsq(self._wheels, v[:3], rcond=None)[0]
        if self._free is not None:
            R = np.empty(9)
            a = self._free[1]
            mujoco.mju_quat2Mat(R, self.data.qpos[a + 3 : a + 7])
            v[:3] = R.reshape(3, 3).T @ v[:3]
        return v

    def torque_step(self, q: np.ndarray, force: np.ndarray, dt: float) -> np.ndarray:
        """Run the physics for ``dt`` (s) from ``q`` (the configuration the plant gave last)
        under the actuators' generalised force ``force`` (nv, Pinocchio's velocity order:
        N m, N; a planar root's force and torque in the base frame), held over the period
        as a torque-controlled drive holds its command; the configuration reached, as the
        sensor reads it (:meth:`velocity` gives the velocity). No servo and no gravity
        compensation act: ``force`` is all the motors apply. A floating base's six have no
        motor (a nonzero force there raises :class:`ModelError`); a force beyond a joint's
        limit is clamped there and recorded in :attr:`log` (``saturated``), never silently;
        a joint held at its limit for ``stall_time`` stops the run (:attr:`stop_reason`)."""
        force = np.asarray(force, dtype=float)
        if force.shape != (self.robot.nv,) or not np.isfinite(force).all():
            raise DimensionError(f"force must be {self.robot.nv} finite numbers")
        if self._free is not None and np.abs(force[:6]).max() > 1e-6 * (1.0 + np.abs(force).max()):
            raise ModelError("a floating base has no motor: force[:6] must be 0")
        n = self._periods(q, dt)
        tau = force.copy()
        if self._free is not None:
            tau[:6] = 0.0
        self._record_poses()
        self.log.configuration.append(self.configuration())
        wheels = np.zeros(self._wheels.shape[1])
        if self._planar is not None:  # the base's force and torque into the world
            yaw = self.data.qpos[self._planar[3]]
            c, s = np.cos(yaw), np.sin(yaw)
            tau[0], tau[1] = c * force[0] - s * force[1], s * force[0] + c * force[1]
        limit = self.world.effort.copy()
        if self._wheels.size:  # a wheeled base's force is bounded by its wheels' torques
            limit[:3] = np.inf
        at_limit = np.abs(tau) > limit * (1.0 + 1e-9)
        demand = np.abs(tau)
        np.clip(tau, -limit, limit, out=tau)
        if self._wheels.size:
            wheels, limited = self._wheel_limited(tau)
            at_limit[:3] |= limited
        self.data.ctrl[self._actuators] = tau[self._driven]
        self._stalled = np.where(at_limit, self._stalled + n, 0)
        warnings = self._warnings()
        for _ in range(n):
            mujoco.mj_step(self.model, self.data)
        return self._finish(n, np.abs(tau), at_limit, wheels, demand, warnings)

    def _periods(self, q: np.ndarray, dt: float) -> int:
        """The physics steps of a control period of ``dt`` s from ``q`` (checked to be where
        the plant is)."""
        if not np.allclose(np.asarray(q, dtype=float), self._seen, atol=1e-6):
            raise ModelError(
                "the plant is not at the controller's configuration: call "
                "plant.reset(q0) before running from q0"
            )
        n = round(dt / self.settings.timestep)
        if n < 1 or abs(n * self.settings.timestep - dt) > 1e-9:
            raise DimensionError(
                f"the control period {dt} s must be a whole number of physics "
                f"steps of {self.settings.timestep} s"
            )
        return n

    def _finish(
        self,
        n: int,
        peak: np.ndarray,
        saturated: np.ndarray,
        wheels: np.ndarray,
        demand: np.ndarray,
        warnings: tuple[int, ...],
    ) -> np.ndarray:
        """After a period's ``n`` physics steps: the time, the log, the divergence and stall
        checks; the configuration as the sensor reads it."""
        self.time += n * self.settings.timestep
        mujoco.mj_kinematics(self.model, self.data)  # the bodies' poses at the new state
        self._record(peak, saturated, wheels)
        if self._warnings() != warnings:
            self.stop_reason = (
                f"the simulation diverged at t = {self.time:.3f} s (MuJoCo "
                f"found a bad position, velocity or acceleration)"
            )
            self.data.qpos[:] = self.qpos(self.log.configuration[-1])
            return self._seen.copy()
        self._check(demand)
        self._seen = self._readout.read(self.configuration())
        return self._seen.copy()

    def _warnings(self) -> tuple[int, ...]:
        """MuJoCo's counts of unusable states (bad position, velocity, acceleration)."""
        w, kinds = self.data.warning, mujoco.mjtWarning
        bad = (kinds.mjWARN_BADQPOS, kinds.mjWARN_BADQVEL, kinds.mjWARN_BADQACC)
        return tuple(int(w[k].number) for k in bad)

    def _wheel_limited(self, tau: np.ndarray) -> tuple[np.ndarray, bool]:
        """The wheel torques (N m) of the planar base's force and torque ``tau[:3]``, both
        scaled (``tau`` in place) so that no wheel needs more than its torque limit; and
        whether they had to be."""
        wheel = self._wheel_torques(tau)
        excess = np.abs(wheel).max() / self.world.wheel_limit
        if excess <= 1.0:
            return wheel, False
        tau[:3] /= excess
        return wheel / excess, True

    def _wheel_torques(self, tau: np.ndarray) -> np.ndarray:
        """The wheel torques (N m) that give the planar base's force and torque ``tau[:3]``
        (world x, y, yaw): ``B^T W`` with ``W`` in the base frame (rolling without slip)."""
        yaw = self.data.qpos[self._planar[3]]  # type: ignore[index]
        c, s = np.cos(yaw), np.sin(yaw)
        wrench = np.array([c * tau[0] + s * tau[1], -s * tau[0] + c * tau[1], tau[2]])
        return self._wheels.T @ wrench

    def _servo(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The clamped torque of every robot dof, the torque asked for, which are at their
        limit (a wheeled base's three when its wheels limit it), and the wheel torques (N m,
        empty without wheels)."""
        d, h = self.data, self.settings.timestep
        target = v.copy()
        if self._planar is not None:  # the base twist (base frame) into the world
            yaw = d.qpos[self._planar[3]]
            c, s = np.cos(yaw), np.sin(yaw)
            target[0], target[1] = c * v[0] - s * v[1], s * v[0] + c * v[1]
        error = target - d.qvel[self._dofs]
        if self._free is not None:  # no servo on a floating base: its acceleration taken 0
            error[:6] = 0.0
        self._acc[self._dofs] = self.kv * error + self.kp * self.lag
        mujoco.mj_mulM(self.model, d, self._force, self._acc)  # M(q) acc, sparse
        asked = self._force[self._dofs]
        if self.settings.gravity_compensation:
            asked += d.qfrc_bias[self._dofs]
            if self._free is not None:  # what the floor carries, the joints need not
                asked -= d.qfrc_constraint[self._dofs]
        if self._free is not None:
            asked[:6] = 0.0
        limit = self.world.effort
        tau = np.clip(asked, -limit, limit)
        at_limit = np.abs(asked) > limit
        wheel = np.zeros(0)
        if self._wheels.size:  # the base's force as its wheels can push it
            wheel, limited = self._wheel_limited(tau)
            at_limit[:3] |= limited
        self.lag = np.where(at_limit, self.lag, self.lag + error * h)
        np.clip(self.lag, -self._lag_bound, self._lag_bound, out=self.lag)
        return tau, asked, at_limit, wheel

    def _record(self, peak: np.ndarray, saturated: np.ndarray, wheels: np.ndarray) -> None:
        log = self.log
        log.torque_peak.append(peak)
        log.saturated.append(saturated)
        log.wheel_torque_peak.append(wheels)
        for key, eq in self.world.welds.items():
            log.grasp_force.setdefault(key, []).append(self._grasp_force(eq, key[0]))
        self._record_contacts()

    def _record_contacts(self) -> None:
        """The contacts now of the robot and of the objects it holds: first time and peak
        normal force per pair."""
        m, d = self.model, self.data
        held = {self.world.objects[o] for (o, _), eq in self.world.welds.items() if d.eq_active[eq]}
        wrench = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            a, b = int(c.geom[0]), int(c.geom[1])
            if not self._touches(a, held):
                a, b = b, a
            if not self._touches(a, held):
                continue
            mujoco.mj_contactForce(m, d, i, wrench)
            key = f"{m.geom(a).name}|{m.geom(b).name}"
            entry = self.log.contacts.setdefault(key, [self.time, 0.0])
            entry[1] = max(entry[1], abs(float(wrench[0])))

    def _touches(self, geom: int, held: set[int]) -> bool:
        """Whether a contact of ``geom`` is reported: a robot shape's, or a held object's."""
        m = self.model
        return m.geom_contype[geom] == 1 or int(m.geom_bodyid[geom]) in held

    def object_poses(self) -> dict[str, np.ndarray]:
        """The free objects' poses now (4x4, world)."""
        out = {}
        for name, body in self.world.objects.items():
            T = np.eye(4)
            T[:3, :3] = self.data.xmat[body].reshape(3, 3)
            T[:3, 3] = self.data.xpos[body]
            out[name] = T
        return out

    def _record_poses(self) -> None:
        """The free objects' poses at the start of a control period (the controller's
        ``q`` of that step)."""
        for name, T in self.object_poses().items():
            self.log.object_poses.setdefault(name, []).append(T)

    def _grasp_force(self, eq: int, obj: str) -> np.ndarray:
        """Force (N, world) of weld ``eq`` on the object: its constraint rows' ``J^T f`` on
        the object's free joint's translation."""
        d, m = self.data, self.model
        if not d.eq_active[eq]:
            return np.zeros(3)
        rows = (d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id == eq)
        force = np.where(rows, d.efc_force, 0.0)
        qfrc = np.zeros(m.nv)
        mujoco.mj_mulJacTVec(m, d, qfrc, force)
        dof = m.jnt_dofadr[m.body_jntadr[self.world.objects[obj]]]
        return qfrc[dof : dof + 3].copy()

    def _check(self, demand: np.ndarray) -> None:
        """:attr:`stop_reason` when a joint stalls at its limit."""
        stall = round(self.settings.stall_time / self.settings.timestep)
        stalled = np.flatnonzero(self._stalled >= stall)
        if stalled.size:
            k = int(stalled[np.argmax(demand[stalled] / self.world.effort[stalled])])
            slide = (
                self.model.jnt_type[self.model.dof_jntid[self._dofs[k]]]
                == mujoco.mjtJoint.mjJNT_SLIDE
            )
            unit = "N" if slide else "N m"
            wheels = " (or its wheels' limit)" if self.planar and k < 3 else ""
            self.stop_reason = (
                f"actuator limit too low: {self.dof_name(k)} asked for {demand[k]:.1f} {unit} "
                f"(limit {self.world.effort[k]:.1f} {unit}{wheels}) for "
                f"{self.settings.stall_time:g} s, at t = {self.time:.2f} s"
            )

    def dof_name(self, k: int) -> str:
        """The name of the robot's ``k``-th velocity (Pinocchio order)."""
        return self.model.joint(self.model.dof_jntid[self._dofs[k]]).name
