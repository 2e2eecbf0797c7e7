"""A robot a user brings, with a URDF of its own: errors that point at the fault (a mistyped
file name, a mimic joint that empties its leader's range, a locked wheel, a wheel radius off
its geometry, cylinder or mesh)."""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import wholebody
from wholebody import ConfigError, ModelError
from wholebody.resources import robots_dir
from wholebody.robot.urdf import example_robot_data_share

needs_robot_data = pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="example-robot-data is not installed (pip install '.[robots]' from the checkout)",
)


def copy_robot(tmp_path: Path, name: str) -> Path:
    """A bundled robot's directory copied to ``tmp_path`` (its robot.toml only when its URDF
    is read from a package)."""
    dst = tmp_path / name
    if (robots_dir() / name / "robot.urdf").is_file():
        shutil.copytree(robots_dir() / name, dst)
    else:
        dst.mkdir()
        shutil.copy(robots_dir() / name / "robot.toml", dst / "robot.toml")
    return dst


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, f"fixture text {old!r} not found in {path.name}"
    path.write_text(text.replace(old, new, 1))


@needs_robot_data
def test_a_mistyped_file_in_an_installed_package_is_told_from_a_missing_package(tmp_path):
    """The package is there, the file is not: the message says so and names the near files,
    with no install hint (installing would not help)."""
    d = copy_robot(tmp_path, "ur5")
    edit(d / "robot.toml", "ur5_robot.urdf", "ur5_robt.urdf")
    with pytest.raises(ConfigError) as info:
        wholebody.load_robot(d)
    text = str(info.value)
    assert "package 'example-robot-data' is at" in text and "has no 'ur5_robt.urdf'" in text
    assert "ur5_robot.urdf" in text.split("nearest names there:")[1]
    assert "not found" not in text and "install" not in text
    edit(d / "robot.toml", "example-robot-data/", "example-robot-dta/")
    with pytest.raises(ConfigError, match=r"not found.*nearest packages there: example-robot-data"):
        wholebody.load_robot(d)


INERTIAL = (
    '<inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" '
    'ixz="0" iyz="0"/></inertial>'
)
MIMIC_URDF = f"""<?xml version="1.0"?>
<robot name="gripper">
  <link name="base">{INERTIAL}</link>
  <link name="left">{INERTIAL}</link>
  <link name="right">{INERTIAL}</link>
  <joint name="finger_left" type="revolute"><parent link="base"/><child link="left"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.548" effort="1" velocity="1"/></joint>
  <joint name="finger_right" type="revolute"><parent link="base"/><child link="right"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.548" effort="1" velocity="1"/>
    <mimic joint="finger_left" multiplier="-1" offset="0"/></joint>
</robot>
"""


def small_robot(tmp_path: Path, urdf: str, toml: str = "") -> Path:
    """A robot directory of a URDF text and a robot.toml of ``toml`` after [robot]."""
    d = tmp_path / "small"
    d.mkdir(exist_ok=True)
    (d / "robot.urdf").write_text(urdf)
    (d / "robot.toml").write_text(
        f'format = 1\n[robot]\nname = "small"\nurdf = "robot.urdf"\n{toml}'
    )
    return d


def test_a_mimic_joint_that_empties_its_leaders_range_is_named(tmp_path):
    """The URDF gives both fingers [0, 0.548]; the follower's multiplier -1 makes that
    [-0.548, 0] for the leader, which leaves it the point 0: the message names the follower
    and the narrowing (not a missing <limit>) and suggests locking the leader, which then
    loads."""
    d = small_robot(tmp_path, MIMIC_URDF)
    with pytest.raises(ModelError) as info:
        wholebody.load_robot(d)
    text = " ".join(str(info.value).split())
    assert "'finger_left' cannot move: its limits [0, 0.548]" in text
    assert "'finger_right' (q = -1 q_finger_left + 0; limits [0, 0.548], so [-0.548, 0]" in text
    assert "lock 'finger_left' in [locked]" in text and "means 0 and 0" not in text
    small_robot(tmp_path, MIMIC_URDF, "[locked]\nfinger_left = 0.0\n")
    robot = wholebody.load_robot(d)
    assert robot.nu == 0 and robot.locked == {"finger_left": 0.0, "finger_right": 0.0}


@needs_robot_data
def test_a_locked_wheel_is_said_to_be_locked(tmp_path):
    d = copy_robot(tmp_path, "tiago_dual")
    edit(d / "robot.toml", '"caster_*" = 0.0', '"caster_*" = 0.0\n"wheel_*" = 0.0')
    with pytest.raises(ConfigError, match=r"\[base.wheels\].*'wheel_left_joint' is locked"):
        wholebody.load_robot(d)


def test_a_wheel_radius_two_percent_off_its_cylinder_is_refused(tmp_path):
    """2 % off the URDF's 0.08 m cylinders: the base would drive 2 % off its command."""
    d = copy_robot(tmp_path, "mobile_humanoid")
    edit(d / "robot.toml", "wheel_radius = 0.08 ", "wheel_radius = 0.0816 ")
    with pytest.raises(ConfigError, match=r"wheel_radius.*radius of 0\.08 m.*2\.0% off"):
        wholebody.load_robot(d)


def prism_stl(radius: float, width: float, sides: int = 32) -> str:
    """An ASCII STL of a regular prism about the y axis: its vertices at ``radius`` from it
    (m), ``width`` wide."""
    ring = [
        (radius * math.cos(2 * math.pi * k / sides), radius * math.sin(2 * math.pi * k / sides))
        for k in range(sides)
    ]
    facets = []
    for k in range(sides):
        (x0, z0), (x1, z1) = ring[k], ring[(k + 1) % sides]
        a, b = (x0, -width / 2, z0), (x1, -width / 2, z1)
        c, e = (x1, width / 2, z1), (x0, width / 2, z0)
        facets += [(a, b, c), (a, c, e), ((0, -width / 2, 0), b, a), ((0, width / 2, 0), e, c)]
    body = "".join(
        "facet normal 0 0 0\n outer loop\n"
        + "".join(f"  vertex {x:.9f} {y:.9f} {z:.9f}\n" for x, y, z in f)
        + " endloop\nendfacet\n"
        for f in facets
    )
    return f"solid wheel\n{body}endsolid wheel\n"


def mesh_wheels(d: Path, radius: float) -> None:
    """The humanoid's wheel cylinders replaced by a mesh file of a ``radius`` prism."""
    (d / "wheel.stl").write_text(prism_stl(radius, 0.05))
    tree = ET.parse(d / "robot.urdf")
    for link in tree.getroot().findall("link"):
        if link.get("name", "").startswith("wheel_"):
            for element in (*link.findall("visual"), *link.findall("collision")):
                geometry = element.find("geometry")
                geometry.clear()
                ET.SubElement(geometry, "mesh", filename="wheel.stl")
                element.find("origin").set("rpy", "0 0 0")
    tree.write(d / "robot.urdf")


def test_a_wheel_given_as_a_mesh_is_checked_by_its_extent_about_the_axis(tmp_path):
    """Mesh wheels of 0.08 m: [base] wheel_radius = 0.08 loads; 0.09 is refused, the
    message naming the mesh's extent."""
    d = copy_robot(tmp_path, "mobile_humanoid")
    mesh_wheels(d, 0.08)
    assert wholebody.load_robot(d).base.type == "mecanum"
    edit(d / "robot.toml", "wheel_radius = 0.08 ", "wheel_radius = 0.09 ")
    with pytest.raises(ConfigError, match=r"radius of 0\.08 m \(the extent of its mesh"):
        wholebody.load_robot(d)
