"""One control period of the node, and what it does on each fault; no ROS here.

:class:`ControlCore` takes the inputs as plain numbers (the node converts the messages)
and returns each period's command ``u`` (rad/s, m/s, in ``u``'s order). Its **modes**:

========== ==================================================== =============================
mode       when                                                 command
========== ==================================================== =============================
WAITING    a required joint (or the odometry) never arrived     zero
STALE      the state is older than ``stale_periods`` periods,   zero (a stop)
           or served that many periods already
HOLDING    no target has arrived yet                            zero: the robot stays put
RUNNING    a fresh state and a target                           the stack's, limited
FAULT      the solver failed or gave a non-finite command       zero (a stop), until a new
                                                                target
========== ==================================================== =============================

A state thus drives at most ``stale_periods`` commands: counting the periods it served, not
only its age, keeps that true when a period runs late (a late period's state arrived after
its deadline, so by age alone it would serve one period more).

Inputs that are not finite or out of range are refused (:mod:`~wholebody.ros.safety`,
:mod:`~wholebody.ros.joint_state`): nothing of them is used, the last good value stays,
and the refusal is counted and reported in the status. A refused joint state is not a
fresh one: the state turns STALE after ``stale_periods`` periods without a good one.

When the first target arrives, every other frame task holds its frame where it is and the
posture task (default stack) holds the posture the robot has then; the controller starts
from rest. After a STALE spell it starts from rest again (integrals cleared) at the targets
it had. Every command passes the :class:`~wholebody.ros.safety.CommandLimiter`; the stops
are the only commands not bound by the acceleration limits.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wholebody.control import Controller
from wholebody.errors import WholebodyError
from wholebody.robot import Robot
from wholebody.ros.joint_state import StateAssembler, StateReading
from wholebody.ros.safety import CommandLimiter, Reach, check_pose, check_twist
from wholebody.ros.stacks import NodeStack
from wholebody.ros.timing import Window

__all__ = ["MODES", "ControlCore", "Tick", "frame_reach"]

MODES = ("WAITING", "STALE", "HOLDING", "RUNNING", "FAULT")

MAX_TWIST = (2.0, 2 * math.pi)
"""The fastest feed-forward taken: 2 m/s, one turn per second."""

REFUSALS_KEPT = 5.0
"""How long (s) a refusal keeps the status at WARN."""


@dataclass(frozen=True)
class Tick:
    """One period's outcome: the command (rad/s, m/s), the mode, the stamp of the state it
    was computed from (ns, the sender's clock; 0 when none was used) and when that state
    arrived (s, monotonic; -inf when none)."""

    u: np.ndarray
    mode: str
    stamp: int
    arrived: float


def frame_reach(robot: Robot, frame: str, travel: float = 0.0) -> Reach:
    """An upper bound of how far ``frame`` can be from the robot's root: the lengths of the
    joint placements from the root to the frame, the frame's own offset and each prismatic
    joint's longest travel (m); a mobile base adds ``travel`` in the plane."""
    model = robot.model
    f = model.frames[robot.frame(frame).index]
    radius = float(np.linalg.norm(f.placement.translation))
    lower, upper = robot.position_limits
    j = f.parentJoint
    while j > 0:
        radius += float(np.linalg.norm(model.jointPlacements[j].translation))
        name = model.names[j]
        if "Prismatic" in model.joints[j].shortname() or model.joints[j].shortname() in (
            "JointModelPX",
            "JointModelPY",
            "JointModelPZ",
        ):
            k = robot.index(name)
            radius += max(abs(lower[k]), abs(upper[k]))
        j = model.parents[j]
    return Reach(radius, travel if robot.base.mobile else 0.0)


class ControlCore:
    """The node's control logic (module docstring).

    Parameters
    ----------
    robot, node_stack
        The robot and what runs on it (:mod:`~wholebody.ros.stacks`).
    dt
        The control period (s).
    stale_periods
        How many periods old a state may be (and how many periods it may serve) before the
        commands stop.
    base_travel
        For a mobile base, how far (m) beyond the arms' reach a target may be from the
        base, in the plane (further ones are refused as out of range).
    clock
        The monotonic clock (s) the refusals are timed with.
    """

    def __init__(
        self,
        robot: Robot,
        node_stack: NodeStack,
        dt: float,
        *,
        stale_periods: float = 3.0,
        base_travel: float = 2.0,
        clock=time.monotonic,
    ) -> None:
        self.robot, self.dt, self.clock = robot, float(dt), clock
        self.node_stack = node_stack
        self.controller = Controller(
            robot, node_stack.stack, node_stack.solver, dt=dt, recovery=False, threads=1
        )
        self.state = StateAssembler(robot)
        self.limiter = CommandLimiter(robot.velocity_limits, robot.acceleration_limits, dt)
        self.stale_periods = stale_periods
        self.max_age = stale_periods * self.dt
        self.tasks = node_stack.tasks
        self.reach = {f: frame_reach(robot, f, base_travel) for f in self.tasks}
        self.targets: dict[str, np.ndarray | None] = dict.fromkeys(self.tasks)
        self.twists: dict[str, tuple[np.ndarray, float] | None] = dict.fromkeys(self.tasks)
        self.mode = "WAITING"
        self.reason = "no joint state yet"
        self.refused = 0
        self.last_refusal: tuple[float, str] | None = None
        self.step_time = Window()
        self.changed = True
        """Whether the mode or a refusal changed since the status was last published."""
        self._active = False  # a target arrived: track
        self._restart = True  # the controller starts from rest at the next RUNNING period
        self._q: np.ndarray | None = None  # the last fresh configuration
        self._arrived = -math.inf  # when the newest state used arrived (s, monotonic)
        self._uses = 0  # the periods it was used in

    # ------------------------------------------------------------------ inputs
    def _refuse(self, what: str, reason: str) -> str:
        self.refused += 1
        self.last_refusal = (self.clock(), f"{what} refused: {reason}")
        self.changed = True
        return self.last_refusal[1]

    def on_joint_state(
        self, names: Sequence[str], positions: Sequence[float], now: float, stamp: int = 0
    ) -> str | None:
        """A ``JointState`` received at ``now`` (s, monotonic; ``stamp``: its header's,
        ns): None when taken, else the refusal."""
        why = self.state.update_joints(names, positions, now, stamp)
        return None if why is None else self._refuse("joint state", why)

    def on_odometry(self, x: float, y: float, yaw: float, now: float) -> str | None:
        """The base pose (odometry frame) received at ``now``: None or the refusal."""
        why = self.state.update_base(x, y, yaw, now)
        return None if why is None else self._refuse("odometry", why)

    def on_target(
        self, frame: str, frame_id: str, position: Sequence[float], quaternion: Sequence[float]
    ) -> str | None:
        """A target of ``frame``'s task: None when taken, else the refusal."""
        root = self._root()
        pose, why = check_pose(frame_id, position, quaternion, self.reach[frame], root)
        if pose is None:
            return self._refuse(f"target of {frame}", why)
        self.targets[frame] = pose
        if self.mode == "FAULT":  # a new target clears a solver fault
            self._restart = True
        self._active = True
        return None

    def on_twist(
        self,
        frame: str,
        frame_id: str,
        linear: Sequence[float],
        angular: Sequence[float],
        now: float,
    ) -> str | None:
        """A feed-forward twist of ``frame``'s target received at ``now``: None or the
        refusal. A twist older than the stale age is dropped."""
        twist, why = check_twist(frame_id, linear, angular, *MAX_TWIST)
        if twist is None:
            return self._refuse(f"twist of {frame}", why)
        self.twists[frame] = (twist, now)
        return None

    def _root(self) -> np.ndarray:
        """Where the robot's root is (world, m): the base's position, or the origin."""
        if self.robot.base.mobile and self._q is not None:
            return np.array([self._q[0], self._q[1], 0.0])
        return np.zeros(3)

    # ------------------------------------------------------------------ a period
    def _set_mode(self, mode: str, reason: str) -> None:
        if mode != self.mode:
            self.changed = True
        self.mode, self.reason = mode, reason

    def tick(self, now: float) -> Tick:
        """The command of the period starting at ``now`` (monotonic, s)."""
        reading = self.state.reading(now)
        if reading.q is None:
            self._restart = True
            self._set_mode("WAITING", "no message yet from: " + ", ".join(reading.missing))
            return Tick(self.limiter.stop(), self.mode, 0, -math.inf)
        self._uses = self._uses + 1 if reading.arrived == self._arrived else 1
        self._arrived = reading.arrived
        if reading.age > self.max_age or self._uses > self.stale_periods:
            self._restart = True
            self._set_mode(
                "STALE",
                f"the newest complete state is {reading.age * 1e3:.1f} "
                f"ms old (at most {self.max_age * 1e3:.1f} ms)",
            )
            return Tick(self.limiter.stop(), self.mode, 0, -math.inf)
        self._q = reading.q
        if not self._active:
            self._set_mode("HOLDING", "no target yet: holding the current pose")
            return Tick(self.limiter.stop(), self.mode, reading.stamp, reading.arrived)
        if self.mode == "FAULT" and not self._restart:
            return Tick(self.limiter.stop(), self.mode, reading.stamp, reading.arrived)
        return self._run(reading, now)

    def _run(self, reading: StateReading, now: float) -> Tick:
        """A RUNNING period at ``reading``'s configuration."""
        q = reading.q
        assert q is not None
        if self._restart:
            self._start(q)
        self._set_targets(q, now)
        start = time.perf_counter()
        try:
            u = self.controller.step(q)
        except WholebodyError as exc:
            self._set_mode("FAULT", f"the solver failed: {exc}")
            return Tick(self.limiter.stop(), self.mode, reading.stamp, reading.arrived)
        self.step_time.add(time.perf_counter() - start)
        if not np.all(np.isfinite(u)):
            self._set_mode("FAULT", "the solver gave a non-finite command")
            return Tick(self.limiter.stop(), self.mode, reading.stamp, reading.arrived)
        limited, clipped = self.limiter.limit(u)
        if clipped:  # the limits' memory keeps what was sent
            self.controller.stack.set_velocity(limited, self.dt)
        self._set_mode("RUNNING", "tracking")
        return Tick(limited, self.mode, reading.stamp, reading.arrived)

    def _start(self, q: np.ndarray) -> None:
        """Start from rest at ``q``: every frame without a target held where it is, the
        posture task at the posture of ``q``, integrals cleared."""
        state = self.robot.update(q)
        for frame, task in self.tasks.items():
            if self.targets[frame] is None:
                self.targets[frame] = state.pose(task.frame).copy()
        posture = self.node_stack.posture
        if posture is not None:
            posture.set_target(self.robot.joint_positions(q))
        self.limiter.stop()
        self.controller.reset(u0=np.zeros(self.robot.nu))
        self._restart = False

    def _set_targets(self, q: np.ndarray, now: float) -> None:
        """Each task's target and, while fresh, its feed-forward twist."""
        for frame, task in self.tasks.items():
            twist = self.twists[frame]
            fresh = twist is not None and now - twist[1] <= self.max_age
            task.set_target(self.targets[frame], twist[0] if fresh else None)

    def warm_up(self, q: np.ndarray, steps: int = 5) -> None:
        """Run the stack a few steps at ``q`` (targets where the frames are) so that the
        kernels are compiled and loaded before the first period, then forget it all."""
        state = self.robot.update(q)
        for task in self.tasks.values():
            task.set_target(state.pose(task.frame).copy())
        if self.node_stack.posture is not None:
            self.node_stack.posture.set_target(self.robot.joint_positions(q))
        self.controller.reset()
        for _ in range(steps):
            self.controller.step(q)
        _ = self.controller.result
        self.controller.reset()
        for task in self.tasks.values():
            task.reset()

    # ------------------------------------------------------------------ reporting
    def level(self) -> str:
        """``OK``, ``WARN`` (holding, a limit clipped or a refusal in the last
        :data:`REFUSALS_KEPT` s), ``ERROR`` (FAULT, WAITING) or ``STALE``."""
        if self.mode == "STALE":
            return "STALE"
        if self.mode in ("FAULT", "WAITING"):
            return "ERROR"
        recent = self.last_refusal is not None and (
            self.clock() - self.last_refusal[0] < REFUSALS_KEPT
        )
        return "WARN" if recent or self.mode == "HOLDING" else "OK"

    def report(self) -> dict[str, str]:
        """The status's key-value pairs: mode, solver status, each task's error with its
        units, the step time's p50/p99 and the refusals."""
        out = {"mode": self.mode, "reason": self.reason}
        if self.mode == "RUNNING":
            out["solver status"] = self.controller.result.status.name
        for frame, task in self.tasks.items():
            e = task.last_error
            out[f"{frame} position error (m)"] = f"{np.linalg.norm(e[:3]):.6f}"
            out[f"{frame} rotation error (rad)"] = f"{np.linalg.norm(e[3:]):.6f}"
        p50, p99 = self.step_time.percentiles(50, 99)
        out["step time p50 (us)"] = f"{p50 * 1e6:.0f}"
        out["step time p99 (us)"] = f"{p99 * 1e6:.0f}"
        out["refused inputs"] = str(self.refused)
        out["last refusal"] = self.last_refusal[1] if self.last_refusal else ""
        return out

    def closest_pairs(self, model, within: float = 0.1, most: int = 5) -> list:
        """The ``most`` closest pairs of a :class:`~wholebody.collision.CollisionModel`
        closer than ``within`` (m) at the last fresh configuration: ``(name, witness point
        a, witness point b, distance)`` (world, m); empty without a model or a state."""
        if model is None or self._q is None:
            return []
        state = self.robot.update(self._q)
        return [
            (p.name, p.point_a, p.point_b, p.distance)
            for p in model.distances(state, within)[:most]
        ]

    def frame_poses(self) -> dict[str, np.ndarray]:
        """Each task frame's pose (4x4, world) at the last fresh configuration (empty
        before one)."""
        if self._q is None:
            return {}
        state = self.robot.update(self._q)
        return {f: state.pose(t.frame).copy() for f, t in self.tasks.items()}
