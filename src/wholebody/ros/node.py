"""``wholebody ros``: the controller as a ROS 2 node named ``wholebody``.

Two threads: an executor thread takes the messages (joint states, odometry, targets,
twists) into the :class:`~wholebody.ros.core.ControlCore`, and the main thread runs the
control loop at absolute deadlines (:class:`~wholebody.ros.timing.Metronome`), phase locked
to the robot's states so that a period starts just after a state arrives
(:func:`~wholebody.ros.timing.phase_error`). Each period: one
:meth:`~wholebody.ros.core.ControlCore.tick`, then the command on three topics, then, when
due, the status (2 Hz, and at once when the mode changes or an input is refused), the
frames' poses and the markers (10 Hz). A lock keeps the two threads off the core at once.

The kernels are compiled and the stack run a few times before the loop starts, so that the
first periods meet their deadlines; the node's first status (mode WAITING) says it is ready.
On SIGINT or SIGTERM the loop ends, one zero command is published (and its delivery awaited
for up to 0.5 s), and the process exits.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from collections.abc import Sequence

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from wholebody.collision import CollisionModel
from wholebody.ros import interface as topics
from wholebody.ros import messages as msgs
from wholebody.ros.core import ControlCore
from wholebody.ros.spinner import Spinner
from wholebody.ros.timing import Metronome, Window, phase_error

__all__ = ["WholebodyNode", "run_node"]

STATUS_PERIOD = 0.5  # s
TELEMETRY_PERIOD = 0.1  # s
LEAD = 0.2
"""Where in the period the node's deadlines lock, after the robot's states (periods)."""
PHASE_GAIN = 0.2
"""The fraction of the phase error corrected per period (the lock settles in ~10 periods)."""
SENSOR_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
"""Joint states, odometry, twists: best effort matches publishers of either reliability."""
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class WholebodyNode:
    """The ROS side of a :class:`ControlCore` (module docstring)."""

    def __init__(
        self, core: ControlCore, rate: float, collision: CollisionModel | None = None
    ) -> None:
        self.core, self.robot = core, core.robot
        self.period = 1.0 / rate
        self.collision = collision
        self.lock = threading.Lock()
        self.node = rclpy.create_node("wholebody")
        self._subscribe()
        self._advertise()
        self.metronome = Metronome(self.period)
        self.command_period, self.latency = Window(), Window()
        self._last_publish: float | None = None
        self._status_due = self._telemetry_due = 0.0
        self.spinner = Spinner(self.node)

    # ------------------------------------------------------------------ topics
    def _subscribe(self) -> None:
        node, robot = self.node, self.robot
        node.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state, SENSOR_QOS)
        if robot.base.mobile:
            node.create_subscription(Odometry, topics.ODOM, self._on_odometry, SENSOR_QOS)
        for frame in self.core.tasks:
            node.create_subscription(
                PoseStamped,
                topics.frame_topic(frame, "target"),
                lambda m, f=frame: self._on_target(f, m),
                10,
            )
            node.create_subscription(
                TwistStamped,
                topics.frame_topic(frame, "twist"),
                lambda m, f=frame: self._on_twist(f, m),
                SENSOR_QOS,
            )

    def _advertise(self) -> None:
        node, robot = self.node, self.robot
        self.pub_command = node.create_publisher(JointState, topics.COMMAND, COMMAND_QOS)
        self.pub_array = node.create_publisher(
            Float64MultiArray, topics.VELOCITY_COMMANDS, COMMAND_QOS
        )
        self.pub_cmd_vel = (
            node.create_publisher(Twist, topics.CMD_VEL, COMMAND_QOS) if robot.base.mobile else None
        )
        self.pub_status = node.create_publisher(DiagnosticArray, topics.STATUS, 10)
        self.pub_markers = node.create_publisher(MarkerArray, topics.MARKERS, 10)
        self.pub_poses = {
            f: node.create_publisher(PoseStamped, topics.frame_topic(f, "pose"), 10)
            for f in self.core.tasks
        }
        self.order = topics.velocity_permutation(robot)
        self.names = list(robot.actuated_joints)
        self.nb = len(robot.base.actuators) if robot.base.mobile else 0
        self._command = msgs.joint_state(self.names, msgs.time_of(0))
        self._array = msgs.velocity_array(np.zeros(robot.nu))

    def _on_joint_state(self, msg: JointState) -> None:
        now = time.monotonic()
        with self.lock:
            self.core.on_joint_state(msg.name, msg.position, now, msgs.stamp_ns(msg.header.stamp))

    def _on_odometry(self, msg: Odometry) -> None:
        now = time.monotonic()
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        with self.lock:
            self.core.on_odometry(p.x, p.y, msgs.yaw_of(o.x, o.y, o.z, o.w), now)

    def _on_target(self, frame: str, msg: PoseStamped) -> None:
        p, o = msg.pose.position, msg.pose.orientation
        with self.lock:
            why = self.core.on_target(
                frame, msg.header.frame_id, (p.x, p.y, p.z), (o.x, o.y, o.z, o.w)
            )
        if why:
            self.node.get_logger().warning(why)

    def _on_twist(self, frame: str, msg: TwistStamped) -> None:
        v, w = msg.twist.linear, msg.twist.angular
        with self.lock:
            why = self.core.on_twist(
                frame, msg.header.frame_id, (v.x, v.y, v.z), (w.x, w.y, w.z), time.monotonic()
            )
        if why:
            self.node.get_logger().warning(why)

    # ------------------------------------------------------------------ the loop
    def run(self, stop: threading.Event) -> None:
        """The control loop until ``stop`` is set, then one zero command."""
        self.spinner.start()
        self._publish_status(time.monotonic())
        arrived = -math.inf
        while not stop.is_set():
            deadline = self.metronome.wait()
            with self.lock:
                tick = self.core.tick(time.monotonic())
            self._publish_command(tick.u, tick.stamp)
            done = time.monotonic()
            if tick.stamp and tick.arrived > arrived:  # a new state: lock onto its phase
                arrived = tick.arrived
                error = phase_error(arrived, deadline, self.period, LEAD * self.period)
                self.metronome.shift(PHASE_GAIN * error)
            if tick.stamp:
                self.latency.add(done - tick.arrived)
            if self._last_publish is not None:
                self.command_period.add(done - self._last_publish)
            self._last_publish = done
            self._telemetry(done)
        self._publish_command(np.zeros(self.robot.nu), 0)
        for pub in (self.pub_command, self.pub_array, self.pub_cmd_vel):
            if pub is not None:
                pub.wait_for_all_acked(rclpy.duration.Duration(seconds=0.5))

    def _publish_command(self, u: np.ndarray, stamp: int) -> None:
        """``u`` on the command topics, stamped ``stamp`` (ns; now when 0). The messages
        are made once and refilled (their names never change)."""
        when = msgs.time_of(stamp) if stamp else self.node.get_clock().now().to_msg()
        self._command.header.stamp = when
        self._command.velocity = u.tolist()
        self.pub_command.publish(self._command)
        self._array.data = u[self.order].tolist()
        self.pub_array.publish(self._array)
        if self.pub_cmd_vel is not None:
            self.pub_cmd_vel.publish(msgs.twist(self.robot.base.matrix @ u[: self.nb]))

    def _telemetry(self, now: float) -> None:
        """The status, poses and markers when due."""
        if self.core.changed or now >= self._status_due:
            self._publish_status(now)
        if now >= self._telemetry_due:
            self._telemetry_due = now + TELEMETRY_PERIOD
            with self.lock:
                poses = self.core.frame_poses()
                pairs = self.core.closest_pairs(self.collision) if poses else []
                targets = dict(self.core.targets)
            stamp = self.node.get_clock().now().to_msg()
            for frame, T in poses.items():
                self.pub_poses[frame].publish(msgs.pose_stamped(T, "world", stamp))
            self.pub_markers.publish(msgs.markers(targets, poses, pairs, stamp))

    def _publish_status(self, now: float) -> None:
        with self.lock:
            values = self.core.report()
            level, message = self.core.level(), f"{self.core.mode}: {self.core.reason}"
            self.core.changed = False
        p50, p99 = self.command_period.percentiles(50, 99)
        l50, l99 = self.latency.percentiles(50, 99)
        values.update(
            {
                "rate (Hz)": f"{1.0 / self.period:g}",
                "missed periods": str(self.metronome.missed),
                "command period p50 (us)": f"{p50 * 1e6:.0f}",
                "command period p99 (us)": f"{p99 * 1e6:.0f}",
                "command period max (us)": f"{self.command_period.maximum() * 1e6:.0f}",
                "latency state to command p50 (us)": f"{l50 * 1e6:.0f}",
                "latency state to command p99 (us)": f"{l99 * 1e6:.0f}",
            }
        )
        stamp = self.node.get_clock().now().to_msg()
        self.pub_status.publish(
            msgs.diagnostics(
                "wholebody: controller", self.robot.name, level, message, values, stamp
            )
        )
        self._status_due = now + STATUS_PERIOD

    def close(self) -> None:
        """Stop the executor thread, then the node."""
        self.spinner.close()


def _stop_on_signals(stop: threading.Event) -> None:
    """SIGINT and SIGTERM set ``stop`` (the loop then sends its zero command)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())


def run_node(
    core: ControlCore,
    rate: float,
    ros_args: Sequence[str] = (),
    collision: CollisionModel | None = None,
) -> int:
    """Start ROS, run the node until SIGINT or SIGTERM, stop it; the exit status."""
    stop = threading.Event()
    _stop_on_signals(stop)
    rclpy.init(args=["wholebody", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = WholebodyNode(core, rate, collision)
    try:
        node.run(stop)
    finally:
        node.close()
        rclpy.try_shutdown()
    return 0


def start(
    robot_name: str,
    frames: Sequence[str] | None,
    stack_file: str | None,
    backend: str,
    rate: float,
    ros_args: Sequence[str] = (),
) -> int:
    """``wholebody ros``: load the robot and the stack, compile and warm the kernels, then
    run the node (module docstring)."""
    from wholebody.robot import load_robot
    from wholebody.ros.stacks import default_stack, scenario_stack
    from wholebody.scenarios.runner import make_solver

    robot = load_robot(robot_name)
    solver = make_solver(backend)
    if stack_file is None:
        node_stack = default_stack(robot, frames, solver)
    else:
        node_stack = scenario_stack(robot, stack_file, solver, backend)
    collision = node_stack.collision or _self_collision(robot)
    core = ControlCore(robot, node_stack, 1.0 / rate)
    print(
        f"wholebody: {robot.name} at {rate:g} Hz, {backend}; compiling and warming the "
        "kernels (about a minute the first time on a machine) ...",
        flush=True,
    )
    core.warm_up(robot.home())
    if collision is not None:  # the markers' distance kernel, loaded before the first period
        collision.distances(robot.update(robot.home()), 0.1)
    frames_text = ", ".join(core.tasks)
    print(f"wholebody: ready; targets on /wholebody/<FRAME>/target for {frames_text}", flush=True)
    return run_node(core, rate, ros_args, collision)


def _self_collision(robot):
    """The robot's self-collision pairs for the markers (None if its shapes cannot be
    loaded)."""
    from wholebody.errors import WholebodyError

    try:
        return CollisionModel(robot)
    except WholebodyError:
        return None
