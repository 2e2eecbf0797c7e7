#!/usr/bin/env python3
"""One control step of the paper's robot in wholebody and in its peers (pink, mink, placo).

The problem, built in every library on ``robots/mobile_humanoid/robot.urdf``:

* two 6-D hand tasks (frames ``left_tool`` and ``right_tool``, weight 1 for position and
  orientation), dead-beat gain: every step asks for the whole remaining error
  (pink/mink/placo gain 1 on the displacement ``dq``; wholebody ``kp = 1/dt`` with no
  feed-forward twist, so ``J u dt = e``);
* posture regularisation towards the home posture with the same dead-beat gain and weight
  ``W_POSTURE``, on every joint, and a damping of the base motion (below);
* joint position limits (a step covers at most half of the distance to a limit) and
  velocity limits.

Two formulations: ``single`` (one weighted least-squares QP: hands and posture together,
hard limits) and ``hierarchy`` (hands strictly above posture: hands as equality constraints
in pink, mink and placo (placo "hard" priority), two levels in wholebody).

The Mecanum base. wholebody drives the four wheel speeds ``u_w`` and the base twist (base
frame) is ``B u_w`` (robot.toml); its posture task has zero error on the wheels, so it adds
``W_POSTURE |u_w|^2``. The least-squares optimum never uses the wheels' internal mode (null
space of B: it moves nothing), so ``u_w = B^+ v_b`` and that term is exactly
``W_POSTURE v_b^T (B B^T)^-1 v_b``; ``B B^T`` is diagonal (``diag(r^2/4, r^2/4,
r^2/(4 (lx+ly)^2))``, wheel radius r, half wheel base lx, half track ly), so every peer gets
the same problem from a **holonomic planar base** whose twist carries the diagonal cost
``W_POSTURE (B B^T)^-1`` (625, 625, 138 here) and whose wheels are not modelled (they move
no task frame; the wheel speeds are ``B^+ v_b``). Per peer:

* pink: the same Pinocchio model as wholebody's (a ``JointModelPlanar`` root: SE(2), twist in
  the base frame, exact SE(2) integration), wheel joints fixed; the base cost is a small
  custom ``pink.tasks.Task`` (pink's PostureTask and DampingTask skip the root joint).
* mink: MuJoCo has no planar joint: the base is a chain of two slide joints (world x, y) and a
  hinge (yaw) added to the URDF before MuJoCo loads it; its velocity is the world-frame base
  velocity, integrated linearly (not on SE(2): a second-order difference, |v| w dt^2 / 2 per
  step). The cost is rotation invariant (equal x and y weights), so it is the same cost. The
  base cost is mink's ``DampingTask`` with per-DOF costs; its PostureTask has zero cost on the
  three base joints.
* placo: placo always adds a free-flyer root; it is masked (``mask_fbase``) and the base is
  the same x/y/yaw joint chain as for mink; the base cost is two soft joint tasks whose
  targets follow the current base pose (zero error, so only the damping remains).

What differs, by design of each library (the check below measures it): the error of a hand.
wholebody uses ``[p_d - p; log3(R_d R^T)]`` in world axes with the rows
``diag(I, Jlog3) J``; placo the same error with rows ``J`` (no Jlog3); pink and mink the SE(3)
logarithm in the hand frame with rows ``Jlog6 J_local`` (it couples translation and rotation).
All agree to first order; along a smooth reference the hand positions agree to well under
0.1 mm (``--steps`` also sets the length of the check). With the limits inactive along the
reference (they are), wholebody's projection (SNS) and HQP backends solve the same problem.

Timing: one step = set the hand targets, update the kinematics, solve, integrate (what a
controller does every period), over the same target sequence (both hands on minimum-jerk
reaches, forth and back) with each case's own state. Two schedules, both in the same run:

* **step-interleaved** (the headline): the cases take turns step by step, so every step
  starts after the other libraries' steps have run, with cold caches, as in a controller that
  shares its machine with a simulator or other processes between two periods;
* **block-interleaved**: the cases take turns every ``BLOCK`` (50) steps, so a step follows
  steps of its own case, with warm caches, as in a tight simulation loop.

Each repeat runs both schedules, so that drifts of the machine's speed (over seconds, on a
shared host) hit every case and both schedules alike. The cold schedule
costs the Python libraries more than the C++ one (placo): more of their work is interpreter
state that other processes evict.

    python benchmarks/peers.py [--steps N] [--repeat R] [--check-steps M]

Real robots (``ROBOTS``, for ``benchmarks/control_step.py``): the same problem on robots of
``robots/`` whose URDFs ship in example-robot-data (TIAGo++, the TALOS upper body), wholebody
against pink only, pink on the Pinocchio model wholebody runs on (``robot.model``); TIAGo++'s
differential base is given to pink as :class:`RobotSetup` says.

Peers come from the optional ``bench`` extra (``pip install '.[bench]'`` from the
checkout); a missing one is skipped with a line saying so. ``tests/test_peers.py`` imports
the builders below.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import math
import platform
import re
import tempfile
import time
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

import wholebody
from wholebody.control import Controller
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.resources import robots_dir
from wholebody.robot import robot_catalogue
from wholebody.solvers import Level, ProjectionSolver, Stack
from wholebody.solvers.hqp import HierarchicalQPSolver
from wholebody.tasks import FrameTask, JointPositionLimits, PostureTask, VelocityLimits
from wholebody.tomlreader import tomllib  # the standard library's, or tomli before 3.11

DT = 0.01
HANDS = ("left_tool", "right_tool")
W_HAND = 1.0  # weight of each hand row (position and orientation)
W_POSTURE = 1e-3  # weight of each posture row (rad/s against m/s and rad/s)
LIMIT_GAIN = 0.5  # fraction of the distance to a joint limit one step may cover
PERIOD = 200  # steps of one reach (2 s); the reference goes forth and back
BLOCK = 50  # steps of one case in a row in the warm schedule
# Each hand reaches 10 cm forward, 5 cm inwards, 15 cm up while pitching by -0.4 rad: every
# joint stays >= 0.27 rad from its limits and every speed < 3 % of its limit, so no bound is
# active and all backends solve the same (unconstrained-in-effect) problem.
REACH = (0.10, -0.05, 0.15)  # m; y is mirrored for the right hand
TILT = -0.4  # rad about the world y axis
PROBE_FRACTION = 0.0094  # the largest per-step fraction of a 200-step minimum-jerk reach
BASE_JOINTS = ("base_x", "base_y", "base_yaw")  # the planar chain for mink and placo
BASE_CHAIN_LIMIT = 100.0  # m / rad: the chain's (never reached) position limits
BASE_CHAIN_VELOCITY = 10.0  # m/s, rad/s: the chain's (never reached) velocity limits

SINGLE, HIERARCHY = "single", "hierarchy"


# ---------------------------------------------------------------------- the shared setup
class HandReferences:
    """The hands' references, shared by :class:`Setup` and :class:`RobotSetup`."""

    references: list[MinimumJerkTrajectory]

    def targets(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The hand targets (4x4, world) for the end of step k (forth and back)."""
        s = (k + 1) % (2 * PERIOD)
        t = (s if s <= PERIOD else 2 * PERIOD - s) * DT
        return tuple(ref.sample(t).pose for ref in self.references)  # type: ignore[return-value]


@dataclass
class Setup(HandReferences):
    """The robot, the base cost, the peers' URDF texts and the shared reference."""

    robot: wholebody.Robot
    joints: tuple[str, ...]  # the 19 non-wheel joints, wholebody's order
    base_cost: np.ndarray  # (3,) weight of (vx, vy, wz) in the base frame
    urdf_planar: str  # wheels fixed (for a Pinocchio planar root)
    urdf_chain: str  # wheels fixed, planar x/y/yaw joint chain at the root
    urdf_dir: Path
    q0: np.ndarray
    home: dict[str, float]
    references: list[MinimumJerkTrajectory]
    hands: tuple[str, str] = HANDS  # the (left, right) hand frames

    def base_twist(self, u: np.ndarray) -> np.ndarray:
        """Base twist (vx, vy, wz; base frame) from wholebody's actuated velocity."""
        return self.robot.base.matrix @ u[: len(self.robot.base.wheel_joints)]


def make_setup(robot: wholebody.Robot | None = None) -> Setup:
    robot = robot or wholebody.load_robot("mobile_humanoid")
    wheels = robot.base.wheel_joints
    joints = tuple(j for j in robot.actuated_joints if j not in wheels)
    B = robot.base.matrix
    BBt = B @ B.T
    assert np.allclose(BBt, np.diag(np.diag(BBt)), atol=1e-12), "B B^T is not diagonal"
    base_cost = W_POSTURE / np.diag(BBt)
    urdf = Path(robot.config.urdf)
    q0 = robot.home()
    jp = robot.joint_positions(q0)
    home = {j: float(jp[robot.index(j)]) for j in joints}
    refs = hand_references(robot, q0, HANDS, REACH, TILT)
    return Setup(
        robot,
        joints,
        base_cost,
        _peer_urdf(urdf, wheels, False),
        _peer_urdf(urdf, wheels, True),
        urdf.parent,
        q0,
        home,
        refs,
    )


def hand_references(
    robot: wholebody.Robot,
    q0: np.ndarray,
    hands: tuple[str, str],
    reach: tuple[float, float, float],
    tilt: float,
) -> list[MinimumJerkTrajectory]:
    """One minimum-jerk reach of ``PERIOD`` steps per hand from its pose at ``q0``: moved by
    ``reach`` (m, world; y mirrored for the right hand, the second) and pitched by ``tilt``
    (rad, about the world y axis)."""
    refs = []
    for frame, side in zip(hands, (1.0, -1.0), strict=True):
        start = robot.frame_pose(q0, frame)
        end = start.copy()
        end[:3, 3] += np.array(reach) * (1.0, side, 1.0)
        end[:3, :3] = pin.exp3(np.array([0.0, tilt, 0.0])) @ start[:3, :3]
        refs.append(MinimumJerkTrajectory(start, end, PERIOD * DT))
    return refs


def _peer_urdf(path: Path, wheels: tuple[str, ...], chain: bool) -> str:
    """The robot's URDF with the wheel joints fixed and, if ``chain``, a planar base made of
    two prismatic joints (world x, y) and a revolute yaw joint above the root link."""
    tree = ET.parse(path)
    root = tree.getroot()
    children = {j.find("child").get("link") for j in root.iter("joint")}
    base_link = next(lk.get("name") for lk in root.iter("link") if lk.get("name") not in children)
    for j in root.iter("joint"):
        if j.get("name") in wheels:
            j.set("type", "fixed")
            for tag in ("axis", "limit", "dynamics"):
                for el in j.findall(tag):
                    j.remove(el)
    if chain:
        parent = "planar_world"
        for name in ("planar_world", "planar_x", "planar_y"):
            link = ET.SubElement(root, "link", name=name)
            if name != "planar_world":  # MuJoCo wants mass on a body that has a joint
                inertial = ET.SubElement(link, "inertial")
                ET.SubElement(inertial, "mass", value="0.001")
                ET.SubElement(
                    inertial,
                    "inertia",
                    ixx="1e-6",
                    iyy="1e-6",
                    izz="1e-6",
                    ixy="0",
                    ixz="0",
                    iyz="0",
                )
        for name, kind, axis, child in (
            ("base_x", "prismatic", "1 0 0", "planar_x"),
            ("base_y", "prismatic", "0 1 0", "planar_y"),
            ("base_yaw", "revolute", "0 0 1", base_link),
        ):
            j = ET.SubElement(root, "joint", name=name, type=kind)
            ET.SubElement(j, "parent", link=parent)
            ET.SubElement(j, "child", link=child)
            ET.SubElement(j, "origin", xyz="0 0 0", rpy="0 0 0")
            ET.SubElement(j, "axis", xyz=axis)
            ET.SubElement(
                j,
                "limit",
                lower=str(-BASE_CHAIN_LIMIT),
                upper=str(BASE_CHAIN_LIMIT),
                effort="1000",
                velocity=str(BASE_CHAIN_VELOCITY),
            )
            parent = child
    return ET.tostring(root, encoding="unicode")


def _mujoco_urdf(text: str) -> str:
    """Keep every link a body (the tool frames are links on fixed joints)."""
    compiler = '<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco>'
    return re.sub(r"(<robot[^>]*>)", lambda m: m.group(1) + compiler, text, count=1)


# ---------------------------------------------------------------------- cases
class Case:
    """One library/backend/formulation; ``step`` is what is timed."""

    library: str
    backend: str
    problem: str

    @property
    def name(self) -> str:
        return f"{self.library} {self.backend} ({self.problem})"

    def reset(self) -> None:
        raise NotImplementedError

    def step(self, targets: tuple[np.ndarray, np.ndarray]) -> None:
        raise NotImplementedError

    def hand_positions(self) -> np.ndarray:
        """(2, 3) world positions of the hands at the current configuration."""
        raise NotImplementedError

    def velocity(self) -> np.ndarray:
        """The last step's base twist (base frame) and the 19 joint speeds (wholebody's
        order): (22,)."""
        raise NotImplementedError


class WholebodyCase(Case):
    library = "wholebody"

    def __init__(self, setup: Setup | RobotSetup, backend: str, problem: str) -> None:
        self.setup, self.backend, self.problem = setup, backend, problem
        robot = self.robot = setup.robot
        self.hands = [FrameTask(robot, f, kp=1.0 / DT, weight=W_HAND) for f in setup.hands]
        posture = PostureTask(robot, kp=1.0 / DT, weight=W_POSTURE)
        levels = (
            [Level(self.hands, name="hands"), Level([posture], name="posture")]
            if problem == HIERARCHY
            else [Level([*self.hands, posture])]
        )
        self.stack = Stack(
            robot, levels, [JointPositionLimits(robot, gain=LIMIT_GAIN), VelocityLimits(robot)]
        )
        self.solver = (
            ProjectionSolver() if backend == "projection" else HierarchicalQPSolver(backend)
        )
        self.controller = Controller(robot, self.stack, self.solver, dt=DT)
        self.reset()

    def reset(self) -> None:
        self.q = self.setup.q0.copy()
        self.u = np.zeros(self.robot.nu)
        self.controller.reset()

    def step(self, targets):
        """The one-call step: the targets set, then :meth:`Controller.step` (kinematics,
        solve, integrals, integration in one kernel call)."""
        for hand, target in zip(self.hands, targets, strict=True):
            hand.set_target(target)
        self.u = self.controller.step(self.q)
        self.q = self.controller.q_next.copy()

    def hand_positions(self):
        state = self.robot.update(self.q)
        return np.array([state.position(self.robot.frame(f)) for f in self.setup.hands])

    def velocity(self):
        base = len(self.robot.base.actuators)  # the wheels (or a planar base's twist)
        return np.concatenate([self.setup.base_twist(self.u), self.u[base:]])


def _pink_tasks(setup: Setup | RobotSetup) -> tuple[list, object]:
    """pink's hand tasks (one per hand frame, position and orientation rows weighted
    ``sqrt(W_HAND)``) and its posture task (``sqrt(W_POSTURE)``), gains 1, no damping: the
    same rows as the stacks of every library here."""
    from pink.tasks import FrameTask, PostureTask

    hands = [
        FrameTask(
            f,
            position_cost=math.sqrt(W_HAND),
            orientation_cost=math.sqrt(W_HAND),
            lm_damping=0.0,
            gain=1.0,
        )
        for f in setup.hands
    ]
    return hands, PostureTask(cost=math.sqrt(W_POSTURE), gain=1.0)


class PinkCase(Case):
    library = "pink"

    def __init__(self, setup: Setup, backend: str, problem: str) -> None:
        import pink
        from pink.tasks import Task as PinkTask

        class BaseDamping(PinkTask):
            """Cost on the planar root's twist (pink's posture and damping tasks skip the
            root joint): zero error, rows = the root's three velocity coordinates."""

            def compute_error(self, configuration):
                return np.zeros(3)

            def compute_jacobian(self, configuration):
                return configuration.tangent.eye[:3]

            def __repr__(self):
                return f"BaseDamping(cost={self.cost})"

        self.setup, self.backend, self.problem = setup, backend, problem
        self._pink = pink
        self.model = pin.buildModelFromXML(setup.urdf_planar, pin.JointModelPlanar())
        self.data = self.model.createData()
        m = self.model
        self.iq = np.array([m.joints[m.getJointId(j)].idx_q for j in setup.joints])
        self.iv = np.array([m.joints[m.getJointId(j)].idx_v for j in setup.joints])
        self.q0 = pin.neutral(m)
        self.q0[:4] = setup.q0[:4]  # x, y, cos yaw, sin yaw: the same planar root
        self.q0[self.iq] = [setup.home[j] for j in setup.joints]
        self.hands, self.posture = _pink_tasks(setup)
        self.posture.set_target(self.q0)
        base = BaseDamping(cost=np.sqrt(setup.base_cost), gain=0.0)
        if problem == HIERARCHY:
            self.tasks, self.constraints = [self.posture, base], self.hands
        else:
            self.tasks, self.constraints = [*self.hands, self.posture, base], None
        self.limits = [
            pink.limits.ConfigurationLimit(m, config_limit_gain=LIMIT_GAIN),
            pink.limits.VelocityLimit(m),
        ]
        self.reset()

    def reset(self) -> None:
        self.conf = self._pink.Configuration(self.model, self.data, self.q0.copy())
        self.v = np.zeros(self.model.nv)

    def step(self, targets):
        for hand, target in zip(self.hands, targets, strict=True):
            hand.set_target(pin.SE3(target))
        v = self._pink.solve_ik(
            self.conf,
            self.tasks,
            DT,
            solver=self.backend,
            damping=1e-12,
            limits=self.limits,
            constraints=self.constraints,
            safety_break=False,
        )
        self.v = v
        self.conf.integrate_inplace(v, DT)  # also updates the kinematics for the next step

    def hand_positions(self):
        hands = self.setup.hands
        return np.array([self.conf.get_transform_frame_to_world(f).translation for f in hands])

    def velocity(self):
        return np.concatenate([self.v[:3], self.v[self.iv]])


class MinkCase(Case):
    library = "mink"

    def __init__(self, setup: Setup, backend: str, problem: str) -> None:
        import mink
        import mujoco

        self.setup, self.backend, self.problem = setup, backend, problem
        self._mink = mink
        m = self.model = mujoco.MjModel.from_xml_string(_mujoco_urdf(setup.urdf_chain))

        def jid(name):
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)

        self.iq = np.array([m.jnt_qposadr[jid(j)] for j in setup.joints])
        self.iv = np.array([m.jnt_dofadr[jid(j)] for j in setup.joints])
        self.ib = np.array([m.jnt_dofadr[jid(j)] for j in BASE_JOINTS])
        ibq = np.array([m.jnt_qposadr[jid(j)] for j in BASE_JOINTS])
        self.q0 = np.zeros(m.nq)
        self.q0[ibq] = setup.robot.base_pose(setup.q0)
        self.q0[self.iq] = [setup.home[j] for j in setup.joints]
        self.ibq = ibq
        self.hands = [
            mink.FrameTask(
                f,
                "body",
                position_cost=math.sqrt(W_HAND),
                orientation_cost=math.sqrt(W_HAND),
                gain=1.0,
                lm_damping=0.0,
            )
            for f in HANDS
        ]
        posture_cost = np.full(m.nv, math.sqrt(W_POSTURE))
        posture_cost[self.ib] = 0.0
        self.posture = mink.PostureTask(m, cost=posture_cost, gain=1.0)
        self.posture.set_target(self.q0)
        damping_cost = np.zeros(m.nv)
        damping_cost[self.ib] = np.sqrt(setup.base_cost)
        base = mink.DampingTask(m, cost=damping_cost)
        if problem == HIERARCHY:
            self.tasks, self.constraints = [self.posture, base], self.hands
        else:
            self.tasks, self.constraints = [*self.hands, self.posture, base], None
        robot = setup.robot
        vmax = {j: float(robot.velocity_limits[robot.index(j)]) for j in setup.joints}
        vmax.update(dict.fromkeys(BASE_JOINTS, BASE_CHAIN_VELOCITY))
        self.limits = [mink.ConfigurationLimit(m, gain=LIMIT_GAIN), mink.VelocityLimit(m, vmax)]
        self.reset()

    def reset(self) -> None:
        self.conf = self._mink.Configuration(self.model, self.q0.copy())
        self.v = np.zeros(self.model.nv)

    def step(self, targets):
        SE3 = self._mink.SE3
        for hand, target in zip(self.hands, targets, strict=True):
            hand.set_target(SE3.from_matrix(target))
        v = self._mink.solve_ik(
            self.conf,
            self.tasks,
            DT,
            self.backend,
            damping=1e-12,
            limits=self.limits,
            constraints=self.constraints,
        )
        self.v = v
        self.conf.integrate_inplace(v, DT)

    def hand_positions(self):
        return np.array(
            [self.conf.get_transform_frame_to_world(f, "body").translation() for f in HANDS]
        )

    def velocity(self):
        yaw = self.conf.q[self.ibq[2]] - self.v[self.ib[2]] * DT  # yaw at the step's start
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy, wz = self.v[self.ib]
        return np.concatenate([[c * vx + s * vy, -s * vx + c * vy, wz], self.v[self.iv]])


class PlacoCase(Case):
    library = "placo"
    backend = "eiquadprog"

    def __init__(self, setup: Setup, backend: str, problem: str) -> None:
        import placo

        self.setup, self.problem = setup, problem
        with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as f:
            f.write(setup.urdf_chain)  # placo reads a file (meshes resolve beside it)
        self.robot = robot = placo.RobotWrapper(f.name, placo.Flags.ignore_collisions)
        Path(f.name).unlink()
        self.iv = np.array([robot.get_joint_v_offset(j) for j in setup.joints])
        self.ib = np.array([robot.get_joint_v_offset(j) for j in BASE_JOINTS])
        solver = self.solver = placo.KinematicsSolver(robot)
        solver.mask_fbase(True)
        solver.enable_joint_limits(True)
        solver.enable_velocity_limits(True)
        solver.dt = DT
        prio = "hard" if problem == HIERARCHY else "soft"
        self.hands = []
        for frame in HANDS:
            task = solver.add_frame_task(frame, np.eye(4))
            task.configure(frame, prio, W_HAND, W_HAND)
            self.hands.append(task)
        self.posture = solver.add_joints_task()
        self.posture.set_joints(dict(setup.home))
        self.posture.configure("posture", "soft", W_POSTURE)
        self.base_xy = solver.add_joints_task()
        self.base_xy.configure("base_xy", "soft", float(setup.base_cost[0]))
        self.base_yaw = solver.add_joints_task()
        self.base_yaw.configure("base_yaw", "soft", float(setup.base_cost[2]))
        assert np.isclose(setup.base_cost[0], setup.base_cost[1])
        self.base0 = setup.robot.base_pose(setup.q0)
        self.reset()

    def reset(self) -> None:
        robot = self.robot
        robot.state.q = robot.neutral_state().q
        for j, value in self.setup.home.items():
            robot.set_joint(j, value)
        for j, value in zip(BASE_JOINTS, self.base0, strict=True):
            robot.set_joint(j, float(value))
        robot.update_kinematics()
        self.dq = np.zeros(robot.model.nv)

    def step(self, targets):
        robot = self.robot
        for hand, target in zip(self.hands, targets, strict=True):
            hand.T_world_frame = target
        # the base tasks' targets follow the base: zero error, only the damping remains
        x, y, yaw = (robot.get_joint(j) for j in BASE_JOINTS)
        self.base_xy.set_joints({"base_x": x, "base_y": y})
        self.base_yaw.set_joints({"base_yaw": yaw})
        robot.update_kinematics()
        self.dq = self.solver.solve(True)

    def hand_positions(self):
        self.robot.update_kinematics()
        return np.array([self.robot.get_T_world_frame(f)[:3, 3] for f in HANDS])

    def velocity(self):
        v = self.dq / DT
        yaw = self.robot.get_joint("base_yaw") - v[self.ib[2]] * DT
        c, s = math.cos(yaw), math.sin(yaw)
        vx, vy, wz = v[self.ib]
        return np.concatenate([[c * vx + s * vy, -s * vx + c * vy, wz], v[self.iv]])


PEERS: dict[str, tuple[str, type[Case]]] = {
    "pink": ("pink", PinkCase),
    "mink": ("mink", MinkCase),
    "placo": ("placo", PlacoCase),
}


def peer_available(library: str) -> str | None:
    """None when the peer imports, else the reason it does not."""
    module = PEERS[library][0]
    try:
        importlib.import_module(module)
        if library == "mink":
            importlib.import_module("mujoco")
    except Exception as exc:  # an optional peer: any import failure means "skip"
        return f"{type(exc).__name__}: {exc}"
    return None


def build_case(setup: Setup, library: str, backend: str, problem: str) -> Case:
    if library == "wholebody":
        return WholebodyCase(setup, backend, problem)
    return PEERS[library][1](setup, backend, problem)


# (library, backends, problems)
PLAN: list[tuple[str, tuple[str, ...], tuple[str, ...]]] = [
    ("wholebody", ("projection", "daqp"), (SINGLE, HIERARCHY)),
    ("pink", ("daqp", "proxqp", "osqp"), (SINGLE, HIERARCHY)),
    ("mink", ("daqp", "proxqp", "osqp"), (SINGLE, HIERARCHY)),
    ("placo", ("eiquadprog",), (SINGLE, HIERARCHY)),
]


def build_cases(setup: Setup, say: Callable[[str], None] = print) -> list[Case]:
    cases: list[Case] = []
    for library, backends, problems in PLAN:
        if library != "wholebody":
            why = peer_available(library)
            if why is not None:
                say(f"skipped {library}: not installed ({why}); pip install '.[bench]'")
                continue
        for problem in problems:
            for backend in backends:
                if backend == "osqp" and problem == HIERARCHY:
                    continue  # equality-constrained: osqp only to ~1e-3, not the same problem
                try:
                    cases.append(build_case(setup, library, backend, problem))
                except ImportError as exc:
                    say(f"skipped {library} {backend}: {exc}")
    return cases


# ---------------------------------------------------------------------- real robots
# The rows of benchmarks/control_step.py for robots of robots/ that ship in example-robot-data:
# wholebody against pink on the same Pinocchio model and the problem above (dead-beat hands,
# posture W_POSTURE, position and velocity limits), along a reference per robot that keeps
# every bound inactive (measured by limit_use), so that every backend solves the same problem.
@dataclass(frozen=True)
class RobotPlan:
    """How a robot is benchmarked against pink."""

    robot: str  # the bundled robot (robots/NAME/robot.toml)
    fixed_base: bool  # True: robot.toml without its [base] table and the wheels locked
    reach: tuple[float, float, float]  # m, world axes, left hand (y mirrored for the right)
    tilt: float  # rad about the world y axis, both hands


# The reaches are a few cm: along them the joint nearest a bound is TIAGo's torso lift at 23 %
# of its speed limit (0.07 m/s; TALOS's shoulders at 10 %), and no step uses more than 1.4 %
# of what a position limit allows (limit_use): no bound is active on either robot.
ROBOTS: dict[str, RobotPlan] = {
    "tiago_dual": RobotPlan("tiago_dual", False, (0.06, -0.03, 0.05), -0.2),
    "tiago_dual_fixed": RobotPlan("tiago_dual", True, (0.06, -0.03, 0.05), -0.2),
    "talos_upper": RobotPlan("talos_upper", False, (0.06, -0.03, 0.05), -0.2),
}


@dataclass
class RobotSetup(HandReferences):
    """A robot of ``robots/`` in wholebody, the model pink gets, and the hands' references.

    pink runs on ``robot.model``, the model wholebody runs on (locked joints removed). On a
    mobile base wholebody's base velocities are the wheel speeds ``u_w`` (base twist
    ``v_b = B u_w``, ``B`` of robot.toml's ``[base]``); pink's model has the same planar root
    (twist in the base frame, the same SE(2) integration) with the wheel joints welded (they
    move no task frame), and its velocities are ``v_b``. ``B`` has full column rank (a
    differential drive), so ``u_w = B^+ v_b`` is the one wheel speed making ``v_b``, and pink
    gets wholebody's problem exactly:

    * the twists the wheels cannot make, ``N^T v_b = 0`` (``N`` spans the null space of
      ``B^T``: a differential drive's lateral velocity), as an equality constraint;
    * wholebody's posture rows on the wheels, ``sqrt(W_POSTURE) u_w``, as the rows
      ``sqrt(W_POSTURE) B^+ v_b`` of a cost;
    * the wheels' speed limits ``|u_w| <= v_max`` as the inequalities ``|B^+ v_b| <= v_max``.
    """

    name: str  # the plan's name (ROBOTS)
    robot: wholebody.Robot
    joints: tuple[str, ...]  # the actuated joints other than the base's, wholebody's order
    hands: tuple[str, str]  # the tool frames of the left and right arms
    model: pin.Model  # pink's: robot.model, wheel joints welded
    q0: np.ndarray
    home: dict[str, float]
    references: list[MinimumJerkTrajectory]

    @property
    def mobile(self) -> bool:
        """Whether the robot has a planar root joint (a mobile base)."""
        return self.robot.base.mobile

    @property
    def base(self) -> str:
        """How the base is modelled in both libraries (one line, for the output)."""
        if self.mobile:
            return (
                f"{self.robot.base.type} base kept: wholebody drives the wheel speeds u_w "
                "(v_b = B u_w); pink the planar root's twist v_b, wheels welded, with "
                "N^T v_b = 0 (no lateral velocity) as an equality, the wheels' posture rows "
                "as sqrt(W) B^+ v_b and |B^+ v_b| <= wheel speed limits"
            )
        if ROBOTS[self.name].fixed_base:
            return (
                "base held still (robot.toml without [base], wheels locked): the fixed "
                "model in both libraries"
            )
        return "fixed base (robot.toml): the same model in both libraries"

    def base_twist(self, u: np.ndarray) -> np.ndarray:
        """Base twist (vx, vy, wz; base frame) from wholebody's actuated velocity; empty for a
        fixed base."""
        if not self.mobile:
            return np.zeros(0)
        return self.robot.base.matrix @ u[: len(self.robot.base.actuators)]


def robot_available(name: str) -> str | None:
    """None when the plan's robot loads (its URDF is installed), else the reason."""
    plan = ROBOTS[name]
    for robot, description, available in robot_catalogue():
        if robot == plan.robot:
            return None if available else description
    return f"no robot {plan.robot!r} in robots/"


def fixed_base_toml(text: str) -> str:
    """A robot.toml's text without its ``[base]`` table (a fixed base: the URDF's root link
    at the world origin) and with the base's wheels locked at 0 (without the base they are
    ordinary continuous joints, which would join ``u``)."""
    wheels = tomllib.loads(text).get("base", {}).get("wheels", [])
    lock = [f'"{w}" = 0.0  # the base is held still' for w in wheels]
    out: list[str] = []
    table = None
    for line in text.splitlines():
        header = re.match(r"\s*\[([^\[\]]+)\]\s*(#.*)?$", line)
        if header:
            table = header.group(1).strip()
        if table != "base":
            out.append(line)
        if header and table == "locked":
            out.extend(lock)
            lock = []
    if lock:  # no [locked] table
        out.extend(["", "[locked]", *lock])
    return "\n".join(out) + "\n"


def load_plan_robot(plan: RobotPlan) -> wholebody.Robot:
    """The plan's robot: the bundled one, or its fixed-base copy (loaded from a temporary
    robot.toml; ``package://`` URDF paths resolve from any directory)."""
    if not plan.fixed_base:
        return wholebody.load_robot(plan.robot)
    text = fixed_base_toml((robots_dir() / plan.robot / "robot.toml").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "robot.toml"
        path.write_text(text)
        robot = wholebody.load_robot(path)
    assert not robot.base.mobile, f"{plan.robot}: still a mobile base without [base]"
    return robot


def make_robot_setup(name: str) -> RobotSetup:
    """The robot of ``ROBOTS[name]`` and its references (raises ConfigError when its URDF is
    not installed: see :func:`robot_available`)."""
    plan = ROBOTS[name]
    robot = load_plan_robot(plan)
    base = robot.base
    if base.mobile:
        B = base.matrix
        assert np.linalg.matrix_rank(B) == B.shape[1], f"{name}: B has no full column rank"
    model = robot.model
    if base.wheel_joints:
        ids = [model.getJointId(w) for w in base.wheel_joints]
        model = pin.buildReducedModel(model, ids, robot.home())
    joints = robot.actuated_joints[len(base.actuators) :]
    q0 = robot.home()
    jp = robot.joint_positions(q0)
    home = {j: float(jp[robot.index(j)]) for j in joints}
    hands = (robot.arm("left").tool.name, robot.arm("right").tool.name)
    refs = hand_references(robot, q0, hands, plan.reach, plan.tilt)
    return RobotSetup(name, robot, joints, hands, model, q0, home, refs)


@functools.cache
def _pink_rows() -> tuple[type, type]:
    """pink's pieces for :class:`RobotPinkCase` (defined on first use: pink is optional):
    a task of constant rows ``R`` with zero error (a cost ``|R dq|^2``, or as a constraint
    ``R dq = 0``), and the limit ``|R dq| <= dt v_max``."""
    from pink.limits import Limit
    from pink.tasks import Task

    class Rows(Task):
        """Constant rows (the cost's or constraint's Jacobian), zero error."""

        def __init__(self, rows: np.ndarray, name: str) -> None:
            super().__init__(cost=1.0, gain=0.0, lm_damping=0.0)
            self.rows, self.name = rows, name
            self.zero = np.zeros(rows.shape[0])

        def compute_error(self, configuration):
            return self.zero

        def compute_jacobian(self, configuration):
            return self.rows

        def __repr__(self):
            return f"Rows({self.name}, {self.rows.shape[0]} x {self.rows.shape[1]})"

    class RowsLimit(Limit):
        """``-dt v_max <= rows dq <= dt v_max``."""

        def __init__(self, rows: np.ndarray, v_max: np.ndarray) -> None:
            self.G = np.vstack([rows, -rows])
            self.v_max = np.concatenate([v_max, v_max])

        def compute_qp_inequalities(self, configuration, dt):
            return self.G, dt * self.v_max

    return Rows, RowsLimit


class RobotPinkCase(PinkCase):
    """pink on a :class:`RobotSetup`: :class:`WholebodyCase`'s problem on the same model
    (the base as :class:`RobotSetup` says)."""

    def __init__(self, setup: RobotSetup, backend: str, problem: str) -> None:
        import pink

        self.setup, self.backend, self.problem = setup, backend, problem
        self._pink = pink
        m = self.model = setup.model.copy()
        self.data = m.createData()
        self.iq = np.array([m.joints[m.getJointId(j)].idx_q for j in setup.joints])
        self.iv = np.array([m.joints[m.getJointId(j)].idx_v for j in setup.joints])
        self.q0 = pin.neutral(m)
        if setup.mobile:
            self.q0[:4] = setup.q0[:4]  # x, y, cos yaw, sin yaw: the same planar root
        self.q0[self.iq] = [setup.home[j] for j in setup.joints]
        self.hands, self.posture = _pink_tasks(setup)  # (the posture skips the root)
        self.posture.set_target(self.q0)
        self.limits = [
            pink.limits.ConfigurationLimit(m, config_limit_gain=LIMIT_GAIN),
            pink.limits.VelocityLimit(m),
        ]
        tasks, equalities = self._base(setup, [self.posture])
        if problem == HIERARCHY:
            self.tasks, self.constraints = tasks, [*self.hands, *equalities]
        else:
            self.tasks, self.constraints = [*self.hands, *tasks], equalities or None
        self.reset()

    def _base(self, setup: RobotSetup, tasks: list) -> tuple[list, list]:
        """``tasks`` with the wheels' posture rows, the base's equalities, and the wheels'
        speed limits appended to ``self.limits`` (nothing for a fixed base)."""
        if not setup.mobile:
            return tasks, []
        Rows, RowsLimit = _pink_rows()
        base = setup.robot.base
        root = np.eye(3, self.model.nv)  # the planar root's twist
        Bp = np.linalg.pinv(base.matrix)  # u_w = B^+ v_b
        v_max = setup.robot.velocity_limits[: len(base.actuators)]
        self.limits.append(RowsLimit(Bp @ root, v_max))
        u, s, _ = np.linalg.svd(base.matrix)
        N = u[:, int(np.sum(s > 1e-12 * s.max())) :]  # null space of B^T
        equalities = [Rows(N.T @ root, "base constraint")] if N.shape[1] else []
        return [*tasks, Rows(math.sqrt(W_POSTURE) * Bp @ root, "wheel posture")], equalities

    def velocity(self):
        base = self.v[:3] if self.setup.mobile else np.zeros(0)
        return np.concatenate([base, self.v[self.iv]])


# (library, backends): both problems each
ROBOT_PLAN: list[tuple[str, tuple[str, ...]]] = [
    ("wholebody", ("projection", "daqp")),
    ("pink", ("daqp",)),
]


def build_robot_cases(setup: RobotSetup, say: Callable[[str], None] = print) -> list[Case]:
    """wholebody's and pink's cases of ``ROBOT_PLAN`` on the robot, both problems (pink
    skipped, with a line, when it does not import)."""
    why = peer_available("pink")
    if why is not None:
        say(f"skipped pink on {setup.name}: not installed ({why}); pip install '.[bench]'")
    cases: list[Case] = []
    for problem in (SINGLE, HIERARCHY):
        for library, backends in ROBOT_PLAN:
            if library == "pink" and why is not None:
                continue
            kind = WholebodyCase if library == "wholebody" else RobotPinkCase
            cases.extend(kind(setup, backend, problem) for backend in backends)
    return cases


def limit_use(setup: Setup | RobotSetup, case: WholebodyCase, steps: int) -> tuple[float, float]:
    """The largest share of a bound ``case`` uses over ``steps`` steps of the reference:
    ``(position, velocity)``, the largest ``|u| dt / (LIMIT_GAIN d)`` (``d`` the distance to
    the limit ahead) and ``|u| / v_max`` over joints and steps (1: the bound is active)."""
    robot = setup.robot
    lower, upper = robot.position_limits
    position = velocity = 0.0
    case.reset()
    for k in range(steps):
        jp = robot.joint_positions(case.q)
        case.step(setup.targets(k))
        u = case.u
        ahead = np.where(u > 0, upper - jp, jp - lower)[robot.positional]
        with np.errstate(divide="ignore"):
            position = max(
                position, float(np.max(np.abs(u[robot.positional]) * DT / (LIMIT_GAIN * ahead)))
            )
        velocity = max(velocity, float(np.max(np.abs(u) / robot.velocity_limits)))
    case.reset()
    return position, velocity


# ---------------------------------------------------------------------- checks
def reference_case(cases: list[Case], problem: str) -> Case:
    """wholebody's HQP (daqp) case of the problem: the exact QP solution, the yardstick."""
    return next(
        c
        for c in cases
        if c.library == "wholebody" and c.problem == problem and c.backend == "daqp"
    )


def probe_targets(setup: Setup | RobotSetup) -> tuple[np.ndarray, np.ndarray]:
    """Hand targets one typical step away from the home pose (the reference's peak step:
    1.8 mm along the reach, 3.8 mrad of pitch), for the one-step comparison."""
    out = []
    for ref in setup.references:
        start, end = ref.sample(0.0).pose, ref.sample(PERIOD * DT).pose
        T = start.copy()
        T[:3, 3] += PROBE_FRACTION * (end[:3, 3] - start[:3, 3])
        T[:3, :3] = (
            pin.exp3(PROBE_FRACTION * pin.log3(end[:3, :3] @ start[:3, :3].T)) @ start[:3, :3]
        )
        out.append(T)
    return tuple(out)  # type: ignore[return-value]


def one_step(setup: Setup | RobotSetup, case: Case) -> np.ndarray:
    """The case's velocity (base twist, joint speeds) for :func:`probe_targets` from home."""
    case.reset()
    case.step(probe_targets(setup))
    v = case.velocity().copy()
    case.reset()
    return v


def run_check(
    setup: Setup | RobotSetup, cases: list[Case], steps: int
) -> dict[str, dict[str, float]]:
    """Each case alone over ``steps`` steps of the reference; per case the largest distance
    (m) of each hand from the reference wholebody case's hand at every step, the largest
    tracking error (m) and, for one step from home towards :func:`probe_targets`, the
    largest velocity difference relative to the largest velocity."""
    hands: dict[str, np.ndarray] = {}
    first: dict[str, np.ndarray] = {c.name: one_step(setup, c) for c in cases}
    track: dict[str, float] = {}
    for case in cases:
        case.reset()
        path = np.empty((steps, 2, 3))
        err = 0.0
        for k in range(steps):
            targets = setup.targets(k)
            case.step(targets)
            path[k] = case.hand_positions()
            err = max(err, max(np.linalg.norm(path[k, i] - targets[i][:3, 3]) for i in range(2)))
        hands[case.name] = path
        track[case.name] = err
        case.reset()
    out = {}
    for case in cases:
        ref = reference_case(cases, case.problem)
        dev = np.linalg.norm(hands[case.name] - hands[ref.name], axis=2).max()
        dv = np.abs(first[case.name] - first[ref.name]).max() / np.abs(first[ref.name]).max()
        out[case.name] = {
            "deviation": float(dev),
            "first_step_dv": float(dv),
            "tracking": track[case.name],
            "reference": ref.name,
        }
    return out


# ---------------------------------------------------------------------- timing
def run_timing(
    setup: Setup, cases: list[Case], steps: int, repeat: int
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Step times (us) of every case over ``repeat`` runs of ``steps`` steps in the two
    schedules, ``(cold, warm)``: the cases taking turns step by step, and every ``BLOCK``
    steps. Each repeat runs both, so that drifts of the machine's speed hit both alike."""
    cold: dict[str, list[float]] = {c.name: [] for c in cases}
    warm: dict[str, list[float]] = {c.name: [] for c in cases}
    perf = time.perf_counter
    targets = [setup.targets(k) for k in range(steps)]
    for _ in range(repeat):
        for times, block in ((cold, 1), (warm, BLOCK)):
            for c in cases:
                c.reset()
            for k in range(0, steps, block):
                for c in cases:
                    out = times[c.name]
                    for target in targets[k : k + block]:
                        t0 = perf()
                        c.step(target)
                        out.append(perf() - t0)
    return (
        {name: np.asarray(t) * 1e6 for name, t in cold.items()},
        {name: np.asarray(t) * 1e6 for name, t in warm.items()},
    )


BASE_NOTE = {
    "wholebody": "4 wheel speeds through the Mecanum map B (robot.toml), planar SE(2) root",
    "pink": "Pinocchio planar root (SE(2), base-frame twist), wheels fixed, twist cost "
    "W (B B^T)^-1",
    "mink": "MuJoCo slide x, slide y, hinge yaw (world-frame velocity, linear integration), "
    "wheels fixed, twist cost W (B B^T)^-1",
    "placo": "free-flyer masked; prismatic x, y + revolute yaw chain, wheels fixed, twist "
    "cost W (B B^T)^-1 as soft joint tasks",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps",
        type=int,
        default=400,
        help="timed steps per repeat (one reach forth and back is 400)",
    )
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--check-steps",
        type=int,
        default=None,
        help="steps of the agreement check (default: --steps)",
    )
    args = parser.parse_args()
    # qpsolvers warns at every osqp call that it converts the dense matrices to sparse ones:
    # that conversion is part of pink's and mink's step with osqp, the warning is noise.
    warnings.filterwarnings("ignore", message="Converted matrix")
    setup = make_setup()
    cases = build_cases(setup)
    libraries = sorted({c.library for c in cases}, key=[p[0] for p in PLAN].index)

    check = run_check(setup, cases, args.check_steps or args.steps)
    times, warm = run_timing(setup, cases, args.steps, args.repeat)

    robot = setup.robot
    print(
        f"\none control step, mobile_humanoid (nu = {robot.nu}), dt = {DT} s, "
        f"{args.steps} steps x {args.repeat}; {platform.machine()} "
        f"{platform.processor() or ''}, Python {platform.python_version()}, "
        f"numpy {np.__version__}".replace("  ", " ")
    )
    print(
        "problem: 2 hand tasks (6-D, w = 1) + posture (w = "
        f"{W_POSTURE:g}) + base twist cost + joint position/velocity limits"
    )
    print("  single: one weighted QP; hierarchy: hands strictly above posture")
    print("base model per library:")
    for lib in libraries:
        print(f"  {lib:10s} {BASE_NOTE[lib]}")
    print()
    head = (
        f"{'':33s} {'step-interleaved (cold)':^39s}  {'block-interleaved (warm)':^22s}\n"
        f"{'library':10s} {'backend':11s} {'problem':10s} {'median us':>10s} "
        f"{'p90 us':>9s} {'x wb proj':>10s} {'x wb hqp':>9s}  {'median us':>10s} "
        f"{'x wb hqp':>9s}"
    )
    print(head)
    print("-" * len(head.splitlines()[-1]))
    for problem in (SINGLE, HIERARCHY):
        wb_proj = np.median(times[f"wholebody projection ({problem})"])
        wb_hqp = np.median(times[f"wholebody daqp ({problem})"])
        wb_hqp_warm = np.median(warm[f"wholebody daqp ({problem})"])
        for c in cases:
            if c.problem != problem:
                continue
            t = times[c.name]
            med, med_warm = float(np.median(t)), float(np.median(warm[c.name]))
            backend = (
                "hqp daqp" if (c.library == "wholebody" and c.backend == "daqp") else c.backend
            )
            print(
                f"{c.library:10s} {backend:11s} {problem:10s} {med:10.1f} "
                f"{np.percentile(t, 90):9.1f} {med / wb_proj:10.2f} {med / wb_hqp:9.2f}  "
                f"{med_warm:10.1f} {med_warm / wb_hqp_warm:9.2f}"
            )
    print(
        "x wb proj / x wb hqp: median over wholebody's projection / HQP (daqp) median for "
        "the same problem and schedule, same run"
    )
    print(
        "paper (Niu et al. 2024), for reference: paper's method 40.55 Hz, pseudo-inverse "
        "343.46 Hz; also reported there: 695.76 Hz"
    )

    print(
        f"\nagreement over {args.check_steps or args.steps} steps of the shared reference (max "
        "over steps and hands of the distance to wholebody's hand; tolerance 0.1 mm)"
    )
    print(
        f"{'case':36s} {'vs':28s} {'max dev mm':>11s} {'1-step rel dv':>14s} "
        f"{'tracking mm':>12s}  ok"
    )
    for c in cases:
        r = check[c.name]
        ok = "yes" if r["deviation"] <= 1e-4 else "NO"
        print(
            f"{c.name:36s} {r['reference']:28s} {r['deviation'] * 1e3:11.5f} "
            f"{r['first_step_dv']:14.2e} {r['tracking'] * 1e3:12.3f}  {ok}"
        )

    print("\ntargets (step-interleaved, the headline; block-interleaved in brackets)")
    for problem, peers, factor, wb_names in (
        (SINGLE, ("pink", "mink"), 1.5, ("projection", "daqp")),
        (HIERARCHY, ("placo",), 1.0, ("daqp", "projection")),  # issue 31: both schedules
    ):
        for wb in wb_names:
            for peer in peers:
                rows = [c for c in cases if c.library == peer and c.problem == problem]
                if not rows:
                    continue
                ratios = []
                for sample in (times, warm):
                    w = np.median(sample[f"wholebody {wb} ({problem})"])
                    best = min(rows, key=lambda c, sample=sample: np.median(sample[c.name]))
                    p = np.median(sample[best.name])
                    ratios.append((p / w if problem == SINGLE else w / p, best.name))
                (cold, name), (hot, warm_name) = ratios
                # each schedule against the peer's fastest backend in that schedule
                hot_s = f"{hot:.2f}x" + ("" if warm_name == name else f" against {warm_name}")
                if problem == SINGLE:
                    met = cold >= factor
                    what = f"{cold:.2f}x ({hot_s}) faster than {name} (target >= {factor}x)"
                else:
                    met = max(cold, hot) <= factor
                    what = f"{cold:.2f}x ({hot_s}) {name}'s time (target <= {factor}x)"
                print(f"  wholebody {wb} ({problem}): {what}: {'met' if met else 'NOT met'}")


if __name__ == "__main__":
    main()
