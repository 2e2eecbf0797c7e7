"""Conversions between ROS 2 messages and the numbers the node works with (imports rclpy's
message packages: the ``ros`` extra).

Times: a header stamp is carried as integer nanoseconds (so that a command is stamped with
exactly the stamp of the state it was computed from); poses as 4x4 matrices (m); rotations
as ROS quaternions ``(x, y, z, w)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseStamped, Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Float64MultiArray, Header
from visualization_msgs.msg import Marker, MarkerArray

__all__ = [
    "LEVELS",
    "diagnostics",
    "joint_state",
    "markers",
    "odometry",
    "pose_stamped",
    "quaternion_of",
    "stamp_ns",
    "time_of",
    "twist",
    "velocity_array",
    "yaw_of",
]

LEVELS = {
    "OK": DiagnosticStatus.OK,
    "WARN": DiagnosticStatus.WARN,
    "ERROR": DiagnosticStatus.ERROR,
    "STALE": DiagnosticStatus.STALE,
}


def stamp_ns(stamp: Time) -> int:
    """A header stamp in nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def time_of(ns: int) -> Time:
    """A stamp of ``ns`` nanoseconds."""
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def yaw_of(x: float, y: float, z: float, w: float) -> float:
    """The yaw (rad, about z) of a quaternion (of a planar pose)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_of(R: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion ``(x, y, z, w)`` of a rotation matrix (Shepperd's method)."""
    t = float(R[0, 0] + R[1, 1] + R[2, 2])
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        return ((R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4)
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
    q = [0.0, 0.0, 0.0, 0.0]
    q[i] = s / 4
    q[j] = (R[j, i] + R[i, j]) / s
    q[k] = (R[k, i] + R[i, k]) / s
    q[3] = (R[k, j] - R[j, k]) / s
    return (q[0], q[1], q[2], q[3])


def _pose(T: np.ndarray) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in T[:3, 3])
    o = pose.orientation
    o.x, o.y, o.z, o.w = quaternion_of(T[:3, :3])
    return pose


def pose_stamped(T: np.ndarray, frame_id: str, stamp: Time) -> PoseStamped:
    """A ``PoseStamped`` of the 4x4 pose ``T`` (m)."""
    return PoseStamped(header=Header(stamp=stamp, frame_id=frame_id), pose=_pose(T))


def joint_state(
    names: Sequence[str],
    stamp: Time,
    positions: np.ndarray | None = None,
    velocities: np.ndarray | None = None,
) -> JointState:
    """A ``JointState`` with the given fields (rad or m, rad/s or m/s)."""
    msg = JointState(header=Header(stamp=stamp), name=list(names))
    if positions is not None:
        msg.position = positions.tolist()
    if velocities is not None:
        msg.velocity = velocities.tolist()
    return msg


def velocity_array(u: np.ndarray) -> Float64MultiArray:
    """A ``Float64MultiArray`` of velocities (already in the controller's joint order)."""
    return Float64MultiArray(data=u.tolist())


def twist(v: Sequence[float]) -> Twist:
    """A ``Twist`` of a planar base twist ``(vx m/s, vy m/s, wz rad/s)`` (base frame)."""
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = (float(x) for x in v)
    return msg


def odometry(base: Sequence[float], v: Sequence[float], stamp: Time, child: str) -> Odometry:
    """An ``Odometry`` of the base pose ``(x, y, yaw)`` in ``odom`` and its twist ``(vx, vy,
    wz)`` in the base frame ``child``."""
    msg = Odometry(header=Header(stamp=stamp, frame_id="odom"), child_frame_id=child)
    x, y, yaw = (float(b) for b in base)
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    msg.twist.twist = twist(v)
    return msg


def diagnostics(
    name: str, hardware: str, level: str, message: str, values: Mapping[str, str], stamp: Time
) -> DiagnosticArray:
    """A ``DiagnosticArray`` of one status (``level``: a key of :data:`LEVELS`)."""
    pairs = [KeyValue(key=k, value=v) for k, v in values.items()]
    status = DiagnosticStatus(
        level=LEVELS[level], name=name, message=message, hardware_id=hardware, values=pairs
    )
    return DiagnosticArray(header=Header(stamp=stamp), status=[status])


def _marker(ns: str, index: int, kind: int, stamp: Time, rgba: Sequence[float]) -> Marker:
    m = Marker(
        header=Header(stamp=stamp, frame_id="world"), ns=ns, id=index, type=kind, action=Marker.ADD
    )
    m.pose.orientation.w = 1.0
    m.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    return m


def markers(
    targets: Mapping[str, np.ndarray | None],
    frames: Mapping[str, np.ndarray],
    pairs: Sequence[tuple[str, np.ndarray, np.ndarray, float]],
    stamp: Time,
) -> MarkerArray:
    """RViz markers: each target (green arrow along its x axis) and current frame (blue
    arrow), and each close collision pair (a line between its witness points, red within
    the pair's distance of 1 cm, orange beyond, labelled with the distance in mm)."""
    out = MarkerArray()
    for i, (name, T) in enumerate(frames.items()):
        for ns, pose, rgba in (
            ("frames", T, (0.2, 0.4, 1.0, 1.0)),
            ("targets", targets.get(name), (0.1, 0.9, 0.2, 1.0)),
        ):
            if pose is None:
                continue
            m = _marker(ns, i, Marker.ARROW, stamp, rgba)
            m.pose = _pose(pose)
            m.scale.x, m.scale.y, m.scale.z = 0.1, 0.01, 0.01
            out.markers.append(m)
    for i, (name, a, b, d) in enumerate(pairs):
        m = _marker(
            "collision_pairs",
            i,
            Marker.LINE_LIST,
            stamp,
            (1.0, 0.1, 0.1, 1.0) if d < 0.01 else (1.0, 0.6, 0.0, 1.0),
        )
        m.scale.x = 0.004
        m.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in (a, b)]
        m.text = f"{name}: {d * 1e3:.1f} mm"
        out.markers.append(m)
    return out
