#!/usr/bin/env python3
"""The ROS 2 loop at 100, 500 and 1000 Hz: ``wholebody ros`` against ``wholebody ros-sim``
(kinematic and MuJoCo), as a user's machine runs them: three processes over DDS on this host.

Per case (rate, sim) a node and a simulated robot are started at that rate; once the node
tracks a target (mode RUNNING), this script, a third process, listens for ``--seconds``:

* **command period** p50 / p99 / max (ms): between consecutive ``/wholebody/command``
  messages as this subscriber receives them (the node's own loop jitter plus delivery);
* **latency** p50 / p99 (ms): from the joint state's stamp (the simulated robot's clock
  when it published the state) to this subscriber's receipt of the command computed from
  it: delivery of the state, the wait for the node's next period, the step, delivery of the
  command. The node locks its periods to start 0.2 period after the states arrive, so
  about that much of it is the wait;
* **missed** (%): deadlines the node skipped because a period overran (its status's
  ``missed periods`` over the window) per deadline of the window;
* **step** p50 / p99 (us): the node's control step (its status).

Cases are interleaved over ``--rounds`` rounds (each case once per round); the table gives
the median over rounds of each figure (max: the largest). The robot tracks a target that
moves between two poses 5 cm apart every second, so that the solver works throughout.

    python benchmarks/ros_loop.py [--robot mobile_humanoid] [--seconds 5] [--rounds 2]
"""

from __future__ import annotations

import argparse
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

import wholebody
from wholebody.ros.messages import pose_stamped, stamp_ns, yaw_of

RATES = (100.0, 500.0, 1000.0)
SIMS = ("kinematic", "mujoco")
SRC = Path(wholebody.__file__).resolve().parents[1]


class Case:
    """One node and one simulated robot, and this process listening to them."""

    def __init__(self, robot: wholebody.Robot, frame: str, rate: float, sim: str) -> None:
        self.robot, self.frame, self.rate, self.sim = robot, frame, rate, sim
        domain = random.randint(1, 101)  # 0-101: clear of Linux ephemeral ports
        path = os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])
        env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(domain),
            "PYTHONPATH": path,
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        }
        self.log = tempfile.TemporaryFile(mode="w+")  # noqa: SIM115 (closed in close)
        base = [sys.executable, "-m", "wholebody"]
        rate_arg = ["--rate", f"{rate:g}"]
        self.procs = [
            subprocess.Popen(
                [*base, "ros-sim", robot.name, "--sim", sim, *rate_arg],
                env=env,
                stdout=self.log,
                stderr=subprocess.STDOUT,
            ),
            subprocess.Popen(
                [*base, "ros", robot.name, "--task", frame, *rate_arg],
                env=env,
                stdout=self.log,
                stderr=subprocess.STDOUT,
            ),
        ]
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("ros_loop_bench", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: list[tuple[int, int, bool]] = []  # (receipt ns, stamp ns, moving)
        self.state: JointState | None = None
        self.odom: Odometry | None = None
        self.status: dict[str, str] = {}
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(JointState, "/wholebody/command", self._on_command, reliable)
        self.node.create_subscription(JointState, "/joint_states", self._on_state, 10)
        self.node.create_subscription(Odometry, "/odom", self._on_odom, 10)
        self.node.create_subscription(DiagnosticArray, "/wholebody/status", self._on_status, 10)
        self.target = self.node.create_publisher(PoseStamped, f"/wholebody/{frame}/target", 10)

    def _on_command(self, msg: JointState) -> None:
        self.received.append((time.time_ns(), stamp_ns(msg.header.stamp), any(msg.velocity)))

    def _on_state(self, msg: JointState) -> None:
        self.state = msg

    def _on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def _on_status(self, msg: DiagnosticArray) -> None:
        s = msg.status[0]
        self.status = {kv.key: kv.value for kv in s.values}

    def spin(self, seconds: float, until=lambda: False) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            if any(p.poll() is not None for p in self.procs):
                self.log.seek(0)
                raise SystemExit(f"a process exited:\n{self.log.read()}")
            self.executor.spin_once(timeout_sec=0.005)

    def pose(self) -> np.ndarray:
        robot, q = self.robot, self.robot.neutral()
        for name, value in zip(self.state.name, self.state.position, strict=True):
            j = robot.model.joints[robot.model.getJointId(name)]
            q[j.idx_q : j.idx_q + j.nq] = (math.cos(value), math.sin(value)) if j.nq == 2 else value
        if robot.base.mobile:
            p, o = self.odom.pose.pose.position, self.odom.pose.pose.orientation
            yaw = yaw_of(o.x, o.y, o.z, o.w)
            q[0:4] = p.x, p.y, math.cos(yaw), math.sin(yaw)
        return robot.frame_pose(q, self.frame)

    def send(self, T: np.ndarray) -> None:
        self.target.publish(pose_stamped(T, "world", Time()))

    def measure(self, seconds: float) -> dict[str, float]:
        """Start tracking, then listen for ``seconds`` (module docstring)."""

        def ready() -> bool:
            return bool(
                self.status
                and self.state is not None
                and (self.odom is not None or not self.robot.base.mobile)
                and self.target.get_subscription_count() > 0
            )

        self.spin(300.0, ready)
        start = self.pose()
        other = start.copy()
        other[:3, 3] += (0.05, 0.0, 0.0)
        self.send(other)
        self.spin(10.0, lambda: self.status.get("mode") == "RUNNING")
        self.spin(1.0)  # the first periods of tracking out of the window
        missed0 = int(self.status["missed periods"])
        self.received.clear()
        t0 = time.monotonic()
        for k in range(math.ceil(seconds)):
            self.send(start if k % 2 == 0 else other)
            self.spin(min(1.0, seconds - (time.monotonic() - t0)))
        missed = int(self.status["missed periods"]) - missed0  # the last status (2 Hz)
        return self._figures(missed, time.monotonic() - t0)

    def _figures(self, missed: int, window: float) -> dict[str, float]:
        got = np.array([(r, s) for r, s, _ in self.received], dtype=np.int64)
        period = np.diff(got[:, 0]) / 1e6  # ms
        latency = (got[:, 0] - got[:, 1])[got[:, 1] > 0] / 1e6
        p50, p99 = np.percentile(period, [50, 99])
        l50, l99 = np.percentile(latency, [50, 99])
        return {
            "period_p50": p50,
            "period_p99": p99,
            "period_max": period.max(),
            "latency_p50": l50,
            "latency_p99": l99,
            "missed": 100.0 * missed / (window * self.rate),
            "step_p50": float(self.status["step time p50 (us)"]),
            "step_p99": float(self.status["step time p99 (us)"]),
        }

    def close(self) -> None:
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.log.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="mobile_humanoid")
    ap.add_argument(
        "--frame", default=None, help="the controlled frame (default: the first arm's tool frame)"
    )
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--rates", default=",".join(f"{r:g}" for r in RATES))
    ap.add_argument("--sims", default=",".join(SIMS))
    args = ap.parse_args()
    robot = wholebody.load_robot(args.robot)
    frame = args.frame or next(iter(robot.arms.values())).tool.name
    cases = [(float(r), s) for s in args.sims.split(",") for r in args.rates.split(",")]
    results: dict[tuple[float, str], list[dict[str, float]]] = {c: [] for c in cases}
    for k in range(args.rounds):
        for rate, sim in cases:
            case = Case(robot, frame, rate, sim)
            try:
                results[(rate, sim)].append(case.measure(args.seconds))
            finally:
                case.close()
            print(f"round {k + 1}: {rate:g} Hz {sim} done", file=sys.stderr, flush=True)
    print(
        f"{robot.name} ({robot.nu} velocities), frame {frame}; {args.rounds} rounds of "
        f"{args.seconds:g} s per case, medians over rounds (max: the largest)\n"
    )
    head = (
        "| rate (Hz) | sim | period p50 / p99 / max (ms) | latency p50 / p99 (ms) | "
        "missed (%) | step p50 / p99 (us) |"
    )
    print(head)
    print("|" + "---|" * 6)
    for (rate, sim), rows in results.items():
        med = {k: float(np.median([r[k] for r in rows])) for k in rows[0]}
        worst = max(r["period_max"] for r in rows)
        print(
            f"| {rate:g} | {sim} | {med['period_p50']:.2f} / {med['period_p99']:.2f} / "
            f"{worst:.1f} | {med['latency_p50']:.2f} / {med['latency_p99']:.2f} | "
            f"{med['missed']:.1f} | {med['step_p50']:.0f} / {med['step_p99']:.0f} |"
        )


if __name__ == "__main__":
    main()
