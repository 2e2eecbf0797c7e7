#!/usr/bin/env python3
"""Generate ``robot.urdf`` of a small fixed-base torso with two 7-DOF arms.

A second robot, unrelated to the paper's, that exercises everything wholebody must not
hard-code: a fixed base, a 1-DOF torso, 7-DOF arms (shoulder pitch/roll/yaw, elbow,
wrist yaw/pitch/roll) with other lengths and masses, joint placements given as plain
offsets rather than DH rows, and both arms with the same (not mirrored) joint axes.
Run ``python robots/dual_arm_torso/generate.py`` to rewrite ``robot.urdf``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wholebody.robot.urdf_builder import (
    Joint,
    Link,
    ball_inertial,
    box,
    box_inertial,
    rod_inertial,
    segment,
    sphere,
    trans,
    urdf_document,
)

TORSO_HEIGHT = 0.80  # m, torso yaw joint above the floor
SHOULDER_OFFSET = (0.0, 0.22, 0.45)  # m, left shoulder centre in the torso frame
UPPER_ARM, FOREARM, HAND = 0.30, 0.25, 0.10  # m
UPPER_ARM_MASS, FOREARM_MASS, HAND_MASS, TORSO_MASS, PEDESTAL_MASS = 1.8, 1.2, 0.5, 10.0, 20.0
JOINT_MASS = 0.3
GAP = 0.055  # m: arm segments stop this short of the joint centres (no self-contact at home)
# name, axis, (lower, upper) rad, velocity rad/s, child link
ARM = (
    ("shoulder_pitch", (0.0, -1.0, 0.0), (-1.0, 3.0), 2.0, "shoulder_1"),
    ("shoulder_roll", (1.0, 0.0, 0.0), (-2.5, 2.5), 2.0, "shoulder_2"),
    ("shoulder_yaw", (0.0, 0.0, 1.0), (-1.5, 1.5), 2.0, "upper_arm"),
    ("elbow", (0.0, -1.0, 0.0), (-0.05, 2.4), 2.5, "forearm"),
    ("wrist_yaw", (0.0, 0.0, 1.0), (-1.5, 1.5), 3.0, "wrist_1"),
    ("wrist_pitch", (0.0, -1.0, 0.0), (-1.2, 1.2), 3.0, "wrist_2"),
    ("wrist_roll", (0.0, 0.0, 1.0), (-1.5, 1.5), 3.0, "hand"),
)
MATERIALS = {"light": "0.85 0.87 0.9 1", "blue": "0.25 0.45 0.75 1", "dark": "0.2 0.2 0.22 1"}
ORIGIN = np.zeros(3)
DOWN = np.array([0.0, 0.0, -1.0])


def urdf() -> str:
    pedestal = (0.3, 0.3, TORSO_HEIGHT - 0.05)
    ped_c = np.array([0.0, 0.0, pedestal[2] / 2])
    torso = (0.18, 0.34, 0.5)
    torso_c = np.array([0.0, 0.0, 0.25])
    links = [
        Link(
            "base_link",
            box_inertial(ped_c, PEDESTAL_MASS, pedestal),
            (box(ped_c, pedestal, "dark"),),
        ),
        Link("torso", box_inertial(torso_c, TORSO_MASS, torso), (box(torso_c, torso, "light"),)),
    ]
    joints = [
        Joint(
            "torso_yaw",
            "revolute",
            "base_link",
            "torso",
            trans(0.0, 0.0, TORSO_HEIGHT),
            lower=-1.5,
            upper=1.5,
            velocity=1.0,
            effort=100.0,
        ),
    ]
    offsets = {"shoulder_pitch": None, "elbow": UPPER_ARM, "wrist_yaw": FOREARM}
    for side, s in (("left", 1.0), ("right", -1.0)):
        parent = "torso"
        for name, axis, (lo, hi), vel, child in ARM:
            if name == "shoulder_pitch":
                origin = trans(SHOULDER_OFFSET[0], s * SHOULDER_OFFSET[1], SHOULDER_OFFSET[2])
            else:
                origin = trans(*(DOWN * (offsets.get(name) or 0.0)))
            joints.append(
                Joint(
                    f"{side}_{name}",
                    "revolute",
                    parent,
                    f"{side}_{child}",
                    origin,
                    axis=axis,
                    lower=lo,
                    upper=hi,
                    velocity=vel,
                    effort=20.0,
                )
            )
            parent = f"{side}_{child}"
        links += [
            Link(
                f"{side}_shoulder_1",
                ball_inertial(ORIGIN, JOINT_MASS, 0.05),
                (sphere(ORIGIN, 0.05, "blue"),),
            ),
            Link(f"{side}_shoulder_2", ball_inertial(ORIGIN, JOINT_MASS, 0.05)),
            Link(
                f"{side}_upper_arm",
                rod_inertial(ORIGIN, DOWN * UPPER_ARM, UPPER_ARM_MASS, 0.04, 0.5),
                (segment(DOWN * GAP, DOWN * (UPPER_ARM - GAP), 0.04, "light"),),
            ),
            Link(
                f"{side}_forearm",
                rod_inertial(ORIGIN, DOWN * FOREARM, FOREARM_MASS, 0.035, 0.45),
                (
                    segment(DOWN * GAP, DOWN * (FOREARM - GAP), 0.035, "light"),
                    sphere(ORIGIN, 0.045, "blue"),
                ),
            ),
            Link(f"{side}_wrist_1", ball_inertial(ORIGIN, JOINT_MASS, 0.03)),
            Link(
                f"{side}_wrist_2",
                ball_inertial(ORIGIN, JOINT_MASS, 0.03),
                (sphere(ORIGIN, 0.035, "blue"),),
            ),
            Link(
                f"{side}_hand",
                rod_inertial(ORIGIN, DOWN * HAND, HAND_MASS, 0.03, 0.5),
                (box(DOWN * HAND / 2, (0.03, 0.07, HAND), "dark"),),
            ),
        ]
        for frame, host, point in (
            (
                "shoulder_centre",
                "torso",
                np.array([SHOULDER_OFFSET[0], s * SHOULDER_OFFSET[1], SHOULDER_OFFSET[2]]),
            ),
            ("elbow_centre", "upper_arm", DOWN * UPPER_ARM),
            ("wrist_centre", "forearm", DOWN * FOREARM),
            ("tool", "hand", DOWN * HAND),
        ):
            host_link = host if host == "torso" else f"{side}_{host}"
            links.append(Link(f"{side}_{frame}"))
            joints.append(
                Joint(f"{side}_{frame}_joint", "fixed", host_link, f"{side}_{frame}", trans(*point))
            )
    return urdf_document(
        "dual_arm_torso", links, joints, MATERIALS, "robots/dual_arm_torso/generate.py"
    )


def main() -> None:
    path = Path(__file__).with_name("robot.urdf")
    path.write_text(urdf())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
