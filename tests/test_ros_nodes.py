"""The node and the simulated robot as two processes over DDS, with this test as the
user: it publishes the targets and reads the robot's state and the node's commands and
status (``wholebody ros`` and ``wholebody ros-sim``, the ros extra).

Each robot's test runs one node and one simulated robot, isolated: a random
``ROS_DOMAIN_ID`` for the module, discovery on this host only, and every process killed at
the end whatever happens. The test waits for the node's first status and the first joint
state (the node compiles and warms its kernels before that) rather than for fixed times.
"""

from __future__ import annotations

import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO

import numpy as np
import pytest

import wholebody

rclpy = pytest.importorskip("rclpy", reason="rclpy is not importable: pip install '.[ros]'")

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from wholebody.robot.urdf import example_robot_data_share  # noqa: E402
from wholebody.ros.messages import pose_stamped, stamp_ns, yaw_of  # noqa: E402

pytestmark = pytest.mark.slow

RATE = 100.0
DT = 1.0 / RATE
READY = 240.0  # s: the node's first status (a fresh machine compiles the kernels first)
DOMAIN = random.randint(1, 101)  # this module's ROS domain (0-101: clear of ephemeral ports)
SRC = Path(wholebody.__file__).resolve().parents[1]


class Robot:
    """A node and a simulated robot of one robot, and this process's view of them."""

    def __init__(self, name: str, frame: str, env: dict[str, str]) -> None:
        self.robot = wholebody.load_robot(name)
        self.name, self.frame, self.env = name, frame, env
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, IO[str]] = {}
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=DOMAIN)
        self.node = rclpy.create_node("wholebody_test", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.states: list[JointState] = []
        self.odom: Odometry | None = None
        self.commands: list[JointState] = []
        self.status: list[DiagnosticArray] = []
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(JointState, "/joint_states", self.states.append, reliable)
        self.node.create_subscription(Odometry, "/odom", self._on_odom, 10)
        self.node.create_subscription(
            JointState, "/wholebody/command", self.commands.append, reliable
        )
        self.node.create_subscription(DiagnosticArray, "/wholebody/status", self.status.append, 100)
        self.target = self.node.create_publisher(PoseStamped, f"/wholebody/{frame}/target", 10)

    def _on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def start(self, command: str, *args: str) -> None:
        cmd = [sys.executable, "-m", "wholebody", command, self.name, "--rate", f"{RATE:g}", *args]
        log = tempfile.TemporaryFile(mode="w+")  # noqa: SIM115 (closed in close)
        self.logs[command] = log
        self.procs[command] = subprocess.Popen(
            cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT
        )

    def spin_until(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not done():
            for name, proc in self.procs.items():
                if proc.poll() is not None and name != "dead":
                    out = self.output(name)
                    pytest.fail(f"{name} exited with {proc.returncode} waiting for {what}:\n{out}")
            if time.monotonic() > end:
                pytest.fail(f"no {what} within {timeout} s")
            self.executor.spin_once(timeout_sec=0.01)

    def output(self, name: str) -> str:
        """What a process printed."""
        log = self.logs[name]
        log.seek(0)
        return log.read()

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def q(self) -> np.ndarray:
        """The robot's configuration from its last joint state (and odometry)."""
        msg = self.states[-1]
        joints = dict(zip(msg.name, msg.position, strict=True))
        q = self.robot.neutral()
        for name, value in joints.items():
            j = self.robot.model.joints[self.robot.model.getJointId(name)]
            if j.nq == 2:
                q[j.idx_q : j.idx_q + 2] = math.cos(value), math.sin(value)
            else:
                q[j.idx_q] = value
        if self.robot.base.mobile:
            p, o = self.odom.pose.pose.position, self.odom.pose.pose.orientation
            yaw = yaw_of(o.x, o.y, o.z, o.w)
            q[0:4] = p.x, p.y, math.cos(yaw), math.sin(yaw)
        return q

    def pose(self) -> np.ndarray:
        return self.robot.frame_pose(self.q(), self.frame)

    def send(self, T: np.ndarray) -> None:
        self.target.publish(pose_stamped(T, "world", Time()))

    def last_status(self) -> tuple[int, str, dict[str, str]]:
        s = self.status[-1].status[0]
        return (
            s.level[0] if isinstance(s.level, bytes) else s.level,
            s.message,
            {kv.key: kv.value for kv in s.values},
        )

    def close(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.kill()
            proc.wait(timeout=10)
        for log in self.logs.values():
            log.close()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture(scope="module")
def env() -> dict[str, str]:
    return {
        **os.environ,
        "ROS_DOMAIN_ID": str(DOMAIN),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]),
    }


@pytest.fixture
def robot_pair(request, env) -> Iterator[Robot]:
    name, frame, sim = request.param
    if name != "mobile_humanoid" and example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    pair = Robot(name, frame, env)
    try:
        pair.start("ros-sim", "--sim", sim)
        pair.start("ros")
        pair.spin_until(
            lambda: (
                pair.status
                and pair.states
                and pair.target.get_subscription_count()
                and (pair.odom or not pair.robot.base.mobile)
            ),
            READY,
            "first status and joint state",
        )
        yield pair
    finally:
        pair.close()


def _limits_held(robot: wholebody.Robot, commands: list[JointState]) -> None:
    """Every command inside the velocity limits, and each one that is not a stop (all
    zero: a stale state on a loaded machine, which the node sends at once) inside the
    acceleration limits of the one before."""
    u = np.array([c.velocity for c in commands])
    assert u.shape[1] == robot.nu
    assert np.all(np.abs(u) <= robot.velocity_limits + 1e-9), np.abs(u).max(axis=0)
    ramps = np.any(u[1:], axis=1)
    step = np.abs(np.diff(u, axis=0))[ramps].max(axis=0)
    assert np.all(step <= robot.acceleration_limits * DT + 1e-9), step / DT


def _moving(pair: Robot) -> bool:
    return bool(pair.commands) and bool(np.any(pair.commands[-1].velocity))


def _reach(pair: Robot, goal: np.ndarray) -> float:
    pair.send(goal)
    err = lambda: float(np.linalg.norm(pair.pose()[:3, 3] - goal[:3, 3]))  # noqa: E731
    pair.spin_until(lambda: err() < 1e-3, 20.0, f"{pair.frame} within 1 mm of its target")
    return err()


CASES = [("ur5", "tool0", "kinematic"), ("mobile_humanoid", "right_tool", "kinematic")]


@pytest.mark.parametrize("robot_pair", CASES, ids=[c[0] for c in CASES], indirect=True)
def test_node_reaches_refuses_nan_and_stops_on_stale_state(robot_pair: Robot) -> None:
    pair, robot = robot_pair, robot_pair.robot
    level, message, _ = pair.last_status()
    assert message.startswith(("HOLDING", "WAITING")), message
    start = pair.pose()
    goal = start.copy()
    goal[:3, 3] += (0.05, -0.04, 0.03)
    assert _reach(pair, goal) < 1e-3
    moving = [c for c in pair.commands if np.any(c.velocity)]
    assert moving, "no command moved the robot"
    _limits_held(robot, pair.commands)

    # a NaN target: refused, said so, and the robot stays at the last target
    bad = goal.copy()
    bad[0, 3] = math.nan
    pair.send(bad)
    pair.spin_until(
        lambda: "not finite" in pair.last_status()[2]["last refusal"],
        5.0,
        "status reporting the NaN target",
    )
    level, _, values = pair.last_status()
    assert level != 0 and values["refused inputs"] == "1"  # WARN (STALE on a loaded machine)
    pair.spin_for(0.2)
    assert np.linalg.norm(pair.pose()[:3, 3] - goal[:3, 3]) < 1e-3

    # the robot stops publishing while moving: the commands go to zero within 3 periods
    away = start.copy()
    away[:3, 3] -= (0.05, -0.04, 0.03)
    pair.send(away)
    pair.spin_until(lambda: _moving(pair), 5.0, "a moving command")
    pair.procs["ros-sim"].kill()
    pair.procs["dead"] = pair.procs.pop("ros-sim")
    pair.spin_until(lambda: pair.last_status()[1].startswith("STALE"), 2.0, "status STALE")
    # the node's last state (one the sim sent last; the kill may cut its delivery to one of
    # the two readers): at most 3 commands computed from it, then only zeros
    pair.spin_until(lambda: not _moving(pair), 1.0, "a zero command")  # topics: any order
    stamps = [stamp_ns(c.header.stamp) for c in pair.commands]
    moving = [i for i, c in enumerate(pair.commands) if np.any(c.velocity)]
    last = stamps[moving[-1]]
    assert last in {stamp_ns(m.header.stamp) for m in pair.states[-3:]}
    on_last = [i for i in moving if stamps[i] == last]
    assert 1 <= len(on_last) <= 3, len(on_last)
    assert len(pair.commands) > moving[-1] + 1  # zeros followed
    # a state delivered late may count once more as fresh: then STALE again
    pair.spin_until(lambda: pair.last_status()[0] == 3, 2.0, "status level STALE")


@pytest.mark.parametrize("robot_pair", CASES[:1], ids=["ur5"], indirect=True)
def test_node_sends_one_zero_command_on_sigterm(robot_pair: Robot) -> None:
    pair = robot_pair
    goal = pair.pose()
    goal[:3, 3] += (0.1, 0.1, -0.1)
    pair.send(goal)
    pair.spin_until(lambda: _moving(pair), 5.0, "a moving command")
    node = pair.procs.pop("ros")
    node.send_signal(signal.SIGTERM)
    pair.procs["dead"] = node
    assert node.wait(timeout=10) == 0
    pair.spin_for(0.3)
    assert np.any(pair.commands[-2].velocity) and not np.any(pair.commands[-1].velocity)
