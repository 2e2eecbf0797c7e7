#!/usr/bin/env python3
"""Generate ``robot.urdf`` of the paper's 23-DOF mobile humanoid from its Table 1.

Niu, Zhao, Jin, Zhang, "A Whole-Body Coordinated Motion Control Method for Highly Redundant
Degrees of Freedom Mobile Humanoid Robots", Biomimetics 2024, 9(12), 766, Table 1.

Table 1 (``TABLE_1_*`` below) is the single source of truth of the kinematics: every joint
placement of the URDF is computed from it. Run ``python robots/mobile_humanoid/generate.py``
to rewrite ``robot.urdf`` beside this file; ``tests/test_robot_files.py`` checks that the
committed file equals the generated one.

Conventions and decisions (the paper is silent on all of these; README.md here lists them):

* Modified (Craig) DH: ``T(i-1 -> i) = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(theta_i + q_i)
  TransZ(d_i)``; joint i's URDF origin is the transform at ``q_i = 0`` and its axis the
  child frame's z.
* DH frame 0 (the waist mount) sits at ``WAIST_MOUNT_XYZ`` in the base frame, rotated by pi
  about z, so that the rows marked "left" put the left arm on the robot's +y side and the
  robot faces +x.
* The right arm is the mirror image of the left arm in the sagittal plane: every right-arm
  DH frame is ``S F S`` with ``S = diag(1, -1, 1)`` (frame-0 coordinates) and its joint
  axes are ``-z`` of those frames, so the same joint values give the mirrored posture on
  both sides (and both arms share their limits). Taken literally, the printed right-arm
  rows put its shoulder 26 cm lower than the left one.
* The child link of joint 7 (shoulder rotation) is the upper arm, of joint 9 (forearm
  rotation) the forearm, of joint 11 the hand with its gripper.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from wholebody.robot.urdf_builder import (
    Inertial,
    Joint,
    Link,
    Shape,
    ball_inertial,
    box,
    box_inertial,
    frame_with_z,
    mdh,
    rod_inertial,
    rot_z,
    segment,
    sphere,
    trans,
    urdf_document,
)

PI = math.pi

# Table 1: (alpha_{i-1} [rad], a_{i-1} [m], d_i [m], theta_i offset [rad]).
TABLE_1_WAIST = (
    (-PI / 2, 0.0, 0.0, PI),  # 1
    (-PI / 2, 0.0, 0.377, -PI / 2),  # 2
    (-PI / 2, 0.0, 0.0345, PI),  # 3
)
TABLE_1_LEFT_ARM = (
    (-PI / 2, 0.1445, 0.130, -PI / 2),  # 4  sternoclavicular
    (PI / 2, 0.0, -0.3225, PI / 2),  # 5  shoulder
    (PI / 2, 0.0, 0.0, PI / 2),  # 6  shoulder
    (PI / 2, 0.0, -0.2662, PI / 2),  # 7  shoulder; upper arm 266.2 mm
    (PI / 2, 0.0, 0.0, 0.0),  # 8  elbow
    (-PI / 2, 0.0, -0.2482, 0.0),  # 9  forearm rotation; forearm 248.2 mm
    (PI / 2, 0.0, 0.0, 0.0),  # 10 wrist
    (-PI / 2, 0.0, -0.3361, PI),  # 11 wrist; wrist centre to tool point 336.1 mm
)

# ---------------------------------------------------------------- chosen numbers (README)
# DH frame 0 in the base frame (base frame: on the floor, centre of the wheel rectangle).
# At q = 0 the tool points are then at (0.0955, +-0.467, 0.404) m: 2.7 cm (left) and
# 0.1 cm (right) from the paper's initial hand positions, with a symmetric robot.
WAIST_MOUNT_XYZ = (0.061, 0.0, 0.7475)
WAIST_MOUNT_YAW = PI

WHEEL_RADIUS = 0.08  # m
WHEEL_WIDTH = 0.05  # m
WHEEL_BASE = 0.50  # m, front-rear axle distance
TRACK = 0.44  # m, left-right wheel distance
CHASSIS_SIZE = (0.62, 0.34, 0.22)  # m
CHASSIS_BOTTOM = 0.08  # m above the floor

WAIST_JOINTS = ("waist_pitch", "waist_yaw", "waist_roll")  # Table 1 joints 1, 2, 3
WAIST_LINKS = ("hip", "abdomen", "chest")
ARM_JOINTS = (  # Table 1 joints 4-11 (left) and 12-19 (right), prefixed by the side
    "clavicle",  # - protraction, + retraction
    "shoulder_flexion",  # + raises the arm forward
    "shoulder_abduction",  # + raises the arm sideways
    "shoulder_rotation",  # + external rotation
    "elbow_flexion",  # + flexion; 0 = straight arm
    "forearm_rotation",
    "wrist_flexion",
    "wrist_rotation",  # about the hand's long axis
)
ARM_LINKS = (
    "clavicle",
    "shoulder_1",
    "shoulder_2",
    "upper_arm",
    "elbow",
    "forearm",
    "wrist",
    "hand",
)

# Human-like ranges of motion (rad) in the conventions above: typical adult active ranges
# (AAOS; Norkin & White) trimmed for a robot: trunk flexion and extension 30 deg (symmetric,
# so that the joint-limit term h1, which pulls joints to mid-range, keeps the trunk upright),
# rotation 45, lateral flexion 30; clavicle 20; shoulder flexion 175 / extension 50, abduction 150 /
# adduction 30, rotation 75; elbow 0-145 deg plus 6 deg hyperextension so that the hanging
# zero posture is strictly inside the range; forearm rotation 80; wrist 70; hand roll 90.
WAIST_LIMITS = ((-0.52, 0.52), (-0.79, 0.79), (-0.52, 0.52))
ARM_LIMITS = (
    (-0.35, 0.35),
    (-0.87, 3.05),
    (-0.52, 2.62),
    (-1.31, 1.31),
    (-0.10, 2.53),
    (-1.40, 1.40),
    (-1.22, 1.22),
    (-1.57, 1.57),
)
WAIST_VELOCITY = (1.0, 1.0, 1.0)  # rad/s
ARM_VELOCITY = (1.0, 2.0, 2.0, 2.0, 2.5, 3.0, 3.0, 3.0)  # rad/s
WHEEL_VELOCITY = 25.0  # rad/s: 2 m/s at the rim
WAIST_EFFORT = 300.0  # N m: the physics runs (wholebody.sim) need up to 280 for the torso
ARM_EFFORT = (80.0, 80.0, 80.0, 40.0, 40.0, 15.0, 15.0, 10.0)  # N m
WHEEL_EFFORT = 30.0  # N m

# Masses (kg); upper arm and forearm are the bodies of the paper's gravity energy.
BASE_MASS, WHEEL_MASS, COLUMN_MASS = 40.0, 1.5, 8.0
HIP_MASS, ABDOMEN_MASS, CHEST_MASS, HEAD_MASS = 6.0, 2.0, 15.0, 2.5
CLAVICLE_MASS, SHOULDER_JOINT_MASS, ELBOW_JOINT_MASS, WRIST_JOINT_MASS = 1.0, 0.4, 0.3, 0.2
UPPER_ARM_MASS, FOREARM_MASS, HAND_MASS = 2.0, 1.5, 0.8
# Centre-of-mass fractions along a segment, from its proximal joint.
UPPER_ARM_COM_FRACTION, FOREARM_COM_FRACTION, HAND_COM_FRACTION = 0.45, 0.43, 0.40
# Radii (m) of the cylinders and spheres.
UPPER_ARM_RADIUS, FOREARM_RADIUS, HAND_RADIUS, CLAVICLE_RADIUS = 0.045, 0.038, 0.035, 0.035
SHOULDER_RADIUS, ELBOW_RADIUS, WRIST_RADIUS = 0.05, 0.045, 0.035
GRIPPER_SIZE = (0.04, 0.09, 0.13)  # m, hand-frame axes (z along the hand)
GAP = 0.055  # m: arm segments stop this short of the joint centres (no self-contact at home)

MATERIALS = {
    "white": "0.92 0.92 0.90 1",
    "grey": "0.55 0.57 0.60 1",
    "dark": "0.22 0.24 0.27 1",
    "rubber": "0.08 0.08 0.08 1",
}
MIRROR = np.diag([1.0, -1.0, 1.0, 1.0])
ORIGIN = np.zeros(3)


def chain(rows: tuple[tuple[float, float, float, float], ...]) -> list[np.ndarray]:
    """DH frames 1..n of ``rows`` at q = 0, in the coordinates of the frame before row 1."""
    T, out = np.eye(4), []
    for alpha, a, d, theta in rows:
        T = T @ mdh(alpha, a, d, theta)
        out.append(T)
    return out


def short_of(a: np.ndarray, b: np.ndarray, gap: float) -> np.ndarray:
    """The point ``gap`` metres before b on the segment from a to b."""
    return b - gap * (b - a) / np.linalg.norm(b - a)


def in_frame(F: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Point p (coordinates of F's parent) expressed in frame F."""
    return (np.linalg.inv(F) @ np.append(p, 1.0))[:3]


def base_and_wheels() -> tuple[list[Link], list[Joint]]:
    cz = CHASSIS_SIZE[2]
    chassis_c = np.array([0.0, 0.0, CHASSIS_BOTTOM + cz / 2])
    column_bottom = CHASSIS_BOTTOM + cz
    column_top = WAIST_MOUNT_XYZ[2] - 0.10  # clear of the hip ball
    half = (column_top - column_bottom) / 2
    ends = (np.array([0.0, 0.0, -half]), np.array([0.0, 0.0, half]))
    links = [
        Link(
            "base_link",
            box_inertial(chassis_c, BASE_MASS, CHASSIS_SIZE),
            (box(chassis_c, CHASSIS_SIZE, "dark"),),
        ),
        Link(
            "column", rod_inertial(*ends, COLUMN_MASS, 0.07, 0.5), (segment(*ends, 0.07, "dark"),)
        ),
    ]
    joints = [
        Joint(
            "column_mount",
            "fixed",
            "base_link",
            "column",
            trans(WAIST_MOUNT_XYZ[0], 0.0, column_bottom + half),
        ),
    ]
    along_y = np.eye(4)
    along_y[:3, :3] = frame_with_z(np.array([0.0, 1.0, 0.0]))
    side = WHEEL_MASS * (3 * WHEEL_RADIUS**2 + WHEEL_WIDTH**2) / 12
    wheel_inertia = np.diag([side, WHEEL_MASS * WHEEL_RADIUS**2 / 2, side])
    for name, sx, sy in (
        ("front_left", 1, 1),
        ("front_right", 1, -1),
        ("rear_left", -1, 1),
        ("rear_right", -1, -1),
    ):
        links.append(
            Link(
                f"wheel_{name}_link",
                Inertial(WHEEL_MASS, ORIGIN, wheel_inertia),
                (Shape("cylinder", along_y, (WHEEL_RADIUS, WHEEL_WIDTH), "rubber"),),
            )
        )
        joints.append(
            Joint(
                f"wheel_{name}",
                "continuous",
                "base_link",
                f"wheel_{name}_link",
                trans(sx * WHEEL_BASE / 2, sy * TRACK / 2, WHEEL_RADIUS),
                axis=(0.0, 1.0, 0.0),
                velocity=WHEEL_VELOCITY,
                effort=WHEEL_EFFORT,
            )
        )
    return links, joints


def waist(frames: list[np.ndarray]) -> tuple[list[Link], list[Joint]]:
    """Waist joints 1-3 hanging off DH frame 0 ("waist_mount")."""
    joints = [
        Joint(
            "waist_mount_joint",
            "fixed",
            "base_link",
            "waist_mount",
            trans(*WAIST_MOUNT_XYZ) @ rot_z(WAIST_MOUNT_YAW),
        ),
    ]
    parent, prev = "waist_mount", np.eye(4)
    for F, name, link, (lo, hi), vel in zip(
        frames, WAIST_JOINTS, WAIST_LINKS, WAIST_LIMITS, WAIST_VELOCITY, strict=True
    ):
        joints.append(
            Joint(
                name,
                "revolute",
                parent,
                link,
                np.linalg.inv(prev) @ F,
                lower=lo,
                upper=hi,
                velocity=vel,
                effort=WAIST_EFFORT,
            )
        )
        parent, prev = link, F
    F1, F2, F3 = frames
    hip_a, hip_b = ORIGIN, in_frame(F1, F2[:3, 3])  # pitch axis to the yaw/roll joints
    sc_height = TABLE_1_LEFT_ARM[0][2]
    chest_c = F3[:3, 3] + np.array([0.0, 0.0, sc_height / 2 + 0.04])  # clear of the hip
    chest_size = (0.20, 0.30, sc_height + 0.06)  # frame-0 axes
    chest_size_local = tuple(float(abs(v)) for v in F3[:3, :3].T @ np.array(chest_size))
    neck = F3[:3, 3] + np.array([0.0, 0.0, sc_height + 0.05])
    head_c = F3[:3, 3] + np.array([0.0, 0.0, sc_height + 0.20])
    links = [
        Link("waist_mount"),
        Link(
            "hip",
            rod_inertial(hip_a, hip_b, HIP_MASS, 0.09, 0.5),
            (sphere(ORIGIN, 0.09, "grey"), segment(hip_a, hip_b, 0.09, "grey")),
        ),
        Link("abdomen", ball_inertial(ORIGIN, ABDOMEN_MASS, 0.08), (sphere(ORIGIN, 0.08, "grey"),)),
        Link(
            "chest",
            box_inertial(in_frame(F3, chest_c), CHEST_MASS, chest_size_local),
            (
                box(in_frame(F3, chest_c), chest_size_local, "white"),
                segment(in_frame(F3, neck), in_frame(F3, head_c), 0.04, "grey"),
            ),
        ),
        # The head's two joints are not modelled (as in the paper): a fixed ball.
        Link("head", ball_inertial(ORIGIN, HEAD_MASS, 0.11), (sphere(ORIGIN, 0.11, "white"),)),
    ]
    joints.append(Joint("head_mount", "fixed", "chest", "head", trans(*in_frame(F3, head_c))))
    return links, joints


def arm_link(k: int, name: str, frames: list[np.ndarray]) -> Link:
    """Arm link k (0 = clavicle ... 7 = hand) in its own DH frame ``frames[k]``."""
    Tinv = np.linalg.inv(frames[k])

    def at(i: int) -> np.ndarray:  # origin of DH frame i in link k's frame
        return (Tinv @ frames[i])[:3, 3]

    o = ORIGIN
    if k == 0:  # clavicle: from the SC joint to the shoulder centre
        return Link(
            name,
            rod_inertial(o, at(1), CLAVICLE_MASS, CLAVICLE_RADIUS, 0.5),
            (
                segment(o, short_of(at(1), o, GAP), CLAVICLE_RADIUS, "white"),
                sphere(o, 0.04, "grey"),
            ),
        )
    if k in (1, 2):  # shoulder housings at the shoulder centre
        shapes = (sphere(o, SHOULDER_RADIUS, "grey"),) if k == 1 else ()
        return Link(name, ball_inertial(o, SHOULDER_JOINT_MASS, SHOULDER_RADIUS), shapes)
    if k == 3:  # upper arm; origin at the elbow
        return Link(
            name,
            rod_inertial(at(1), o, UPPER_ARM_MASS, UPPER_ARM_RADIUS, UPPER_ARM_COM_FRACTION),
            (segment(short_of(o, at(1), GAP), short_of(at(1), o, GAP), UPPER_ARM_RADIUS, "white"),),
        )
    if k == 4:
        return Link(
            name,
            ball_inertial(o, ELBOW_JOINT_MASS, ELBOW_RADIUS),
            (sphere(o, ELBOW_RADIUS, "grey"),),
        )
    if k == 5:  # forearm; origin at the wrist
        return Link(
            name,
            rod_inertial(at(4), o, FOREARM_MASS, FOREARM_RADIUS, FOREARM_COM_FRACTION),
            (segment(short_of(o, at(4), GAP), short_of(at(4), o, GAP), FOREARM_RADIUS, "white"),),
        )
    if k == 6:
        return Link(
            name,
            ball_inertial(o, WRIST_JOINT_MASS, WRIST_RADIUS),
            (sphere(o, WRIST_RADIUS, "grey"),),
        )
    wrist = at(6)  # hand with gripper; origin at the tool point
    return Link(
        name,
        rod_inertial(wrist, o, HAND_MASS, HAND_RADIUS, HAND_COM_FRACTION),
        (segment(wrist, 0.4 * wrist, HAND_RADIUS, "grey"), box(0.2 * wrist, GRIPPER_SIZE, "dark")),
    )


def arm(side: str, frames: list[np.ndarray], sign: float) -> tuple[list[Link], list[Joint]]:
    """One arm from its chest-relative DH frames 4..11; ``sign`` = -1 flips the axes."""
    names = [f"{side}_{j}" for j in ARM_JOINTS]
    link_names = [f"{side}_{k}" for k in ARM_LINKS]
    links, joints = [], []
    parent, prev = "chest", np.eye(4)
    for k, (F, name, link, (lo, hi), vel, eff) in enumerate(
        zip(frames, names, link_names, ARM_LIMITS, ARM_VELOCITY, ARM_EFFORT, strict=True)
    ):
        joints.append(
            Joint(
                name,
                "revolute",
                parent,
                link,
                np.linalg.inv(prev) @ F,
                axis=(0.0, 0.0, sign),
                lower=lo,
                upper=hi,
                velocity=vel,
                effort=eff,
            )
        )
        links.append(arm_link(k, link, frames))
        parent, prev = link, F
    # Operational frames at the joint centres (hosted by the link that carries the point)
    # and the tool frame = DH frame 11.
    for frame, host, point in (
        (f"{side}_shoulder_centre", 0, frames[1][:3, 3]),
        (f"{side}_elbow_centre", 4, frames[4][:3, 3]),
        (f"{side}_wrist_centre", 6, frames[6][:3, 3]),
    ):
        links.append(Link(frame))
        joints.append(
            Joint(
                f"{frame}_joint",
                "fixed",
                link_names[host],
                frame,
                trans(*in_frame(frames[host], point)),
            )
        )
    links.append(Link(f"{side}_tool"))
    joints.append(Joint(f"{side}_tool_joint", "fixed", link_names[7], f"{side}_tool", np.eye(4)))
    return links, joints


def urdf() -> str:
    waist_frames = chain(TABLE_1_WAIST)
    F3 = waist_frames[2]
    left = chain(TABLE_1_LEFT_ARM)  # relative to frame 3
    # Mirror across the sagittal plane y0 = 0 (frame-0 coordinates), back into frame 3.
    right = [np.linalg.inv(F3) @ MIRROR @ F3 @ F @ MIRROR for F in left]
    links, joints = base_and_wheels()
    for part in (waist(waist_frames), arm("left", left, 1.0), arm("right", right, -1.0)):
        links += part[0]
        joints += part[1]
    return urdf_document(
        "mobile_humanoid",
        links,
        joints,
        MATERIALS,
        "robots/mobile_humanoid/generate.py from Table 1 of Niu et al. 2024",
    )


def main() -> None:
    path = Path(__file__).with_name("robot.urdf")
    path.write_text(urdf())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
