"""``wholebody ros-sim``: a simulated robot as a ROS 2 node named ``wholebody_sim``.

It publishes ``/joint_states`` (every joint of ``u`` with a position: rad, m; the wheels'
angles; the applied velocities) and, for a mobile base, ``/odom`` (the base pose in
``odom``, its twist in the base frame), every period, and integrates the commands it takes
from ``/wholebody/command`` and ``/wholebody/velocity_commands``
(:class:`~wholebody.ros.simulated.SimulatedRobot`). It runs its own period clock: like a
robot, it does not wait for the controller. A physics run that stops (a joint held at its
torque limit, a divergence) ends the node with its reason and exit status 1.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Sequence

import rclpy
from nav_msgs.msg import Odometry
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from wholebody.ros import interface as topics
from wholebody.ros import messages as msgs
from wholebody.ros.node import COMMAND_QOS
from wholebody.ros.simulated import SimulatedRobot
from wholebody.ros.spinner import Spinner
from wholebody.ros.timing import Metronome

__all__ = ["run_sim", "start"]


class SimNode:
    """The ROS side of a :class:`SimulatedRobot` (module docstring)."""

    def __init__(self, sim: SimulatedRobot) -> None:
        self.sim, self.robot = sim, sim.robot
        self.lock = threading.Lock()
        self.node = rclpy.create_node("wholebody_sim")
        node = self.node
        node.create_subscription(JointState, topics.COMMAND, self._on_command, COMMAND_QOS)
        node.create_subscription(
            Float64MultiArray, topics.VELOCITY_COMMANDS, self._on_array, COMMAND_QOS
        )
        self.pub_joints = node.create_publisher(JointState, topics.JOINT_STATES, 10)
        self.pub_odom = (
            node.create_publisher(Odometry, topics.ODOM, 10) if self.robot.base.mobile else None
        )
        model = self.robot.model
        self.names = [n for n in self.robot.actuated_joints if model.existJointName(n)]
        self.index = [self.robot.index(n) for n in self.names]
        self.spinner = Spinner(node)

    def _on_command(self, msg: JointState) -> None:
        with self.lock:
            why = self.sim.on_command(msg.name, msg.velocity, time.monotonic())
        if why:
            self.node.get_logger().warning(why)

    def _on_array(self, msg: Float64MultiArray) -> None:
        with self.lock:
            why = self.sim.on_array(msg.data, time.monotonic())
        if why:
            self.node.get_logger().warning(why)

    def publish(self) -> None:
        """The state now: joint positions and applied velocities, and the odometry."""
        robot, q = self.robot, self.sim.q
        stamp = self.node.get_clock().now().to_msg()
        jp, u = robot.joint_positions(q), self.sim.last_applied
        self.pub_joints.publish(
            msgs.joint_state(self.names, stamp, positions=jp[self.index], velocities=u[self.index])
        )
        if self.pub_odom is not None:
            nb = len(robot.base.actuators)
            self.pub_odom.publish(
                msgs.odometry(
                    robot.base_pose(q), robot.base.matrix @ u[:nb], stamp, robot.base_frame.name
                )
            )

    def run(self, stop: threading.Event, period: float) -> int:
        """Publish and integrate every ``period`` until ``stop``; the exit status."""
        self.spinner.start()
        self.publish()
        metronome = Metronome(period)
        while not stop.is_set():
            now = metronome.wait()
            with self.lock:
                self.sim.step(now)
            if self.sim.stop_reason:
                print(f"wholebody ros-sim: the physics stopped: {self.sim.stop_reason}", flush=True)
                return 1
            self.publish()
        return 0

    def close(self) -> None:
        """Stop the executor thread, then the node."""
        self.spinner.close()


def run_sim(sim: SimulatedRobot, rate: float, ros_args: Sequence[str] = ()) -> int:
    """Start ROS, run the simulated robot until SIGINT or SIGTERM; the exit status."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(args=["wholebody_sim", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = SimNode(sim)
    try:
        return node.run(stop, 1.0 / rate)
    finally:
        node.close()
        rclpy.try_shutdown()


def start(robot_name: str, sim: str, rate: float, ros_args: Sequence[str] = ()) -> int:
    """``wholebody ros-sim``: the robot at its home posture, then the node."""
    from wholebody.robot import load_robot

    robot = load_robot(robot_name)
    simulated = SimulatedRobot(robot, sim, 1.0 / rate)
    print(
        f"wholebody ros-sim: {robot.name}, {sim}, {rate:g} Hz: publishing /joint_states"
        + (" and /odom" if robot.base.mobile else ""),
        flush=True,
    )
    return run_sim(simulated, rate, ros_args)
