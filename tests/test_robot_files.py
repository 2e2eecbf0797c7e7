"""The committed robot files are the generators' output, load in MuJoCo without self-contact,
and ship inside the wheel so that a non-editable install finds them."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import wholebody
from wholebody.resources import robots_dir

ROBOTS = ["mobile_humanoid", "dual_arm_torso"]
ROOT = Path(__file__).resolve().parents[1]


def load_generator(name: str):
    path = robots_dir() / name / "generate.py"
    spec = importlib.util.spec_from_file_location(f"generate_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", ROBOTS)
def test_committed_urdf_is_the_generated_one(name):
    generated = load_generator(name).urdf()
    committed = (robots_dir() / name / "robot.urdf").read_text()
    assert generated == committed, f"run python robots/{name}/generate.py and commit the result"


@pytest.mark.parametrize("name", ROBOTS)
def test_mujoco_loads_the_urdf_without_self_contact(name):
    mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional 'sim' extra")
    robot = wholebody.load_robot(name)
    model = mujoco.MjModel.from_xml_path(str(robot.config.urdf))
    data = mujoco.MjData(model)
    assert model.njnt == robot.nu - (3 if robot.base.type == "planar" else 0)
    for q in (robot.neutral(), robot.home()):
        jp = robot.joint_positions(q)
        for j in range(model.njnt):
            data.qpos[model.jnt_qposadr[j]] = jp[robot.index(model.joint(j).name)]
        mujoco.mj_forward(model, data)
        pairs = [
            (
                model.body(model.geom_bodyid[c.geom1]).name,
                model.body(model.geom_bodyid[c.geom2]).name,
            )
            for c in data.contact[: data.ncon]
        ]
        assert pairs == []


@pytest.mark.slow
def test_wheel_ships_robots_and_tasks_for_a_non_editable_install(tmp_path):
    pytest.importorskip("hatchling", reason="building the wheel needs hatchling (dev extra)")
    out = tmp_path / "dist"
    subprocess.run(
        [sys.executable, "-m", "hatchling", "build", "-t", "wheel", "-d", str(out)],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    (wheel,) = out.glob("wholebody-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    for name in ROBOTS:
        for f in ("robot.urdf", "robot.toml"):
            assert f"wholebody/_share/robots/{name}/{f}" in names
    assert any(n.startswith("wholebody/_share/tasks/") for n in names)
    # unpacked on its own, imported from elsewhere: the bundled robots are found
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    code = (
        "import wholebody, wholebody.resources as r; "
        "print(wholebody.load_robot('mobile_humanoid').nu, r.share_dir())"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(site), "PATH": ""},
        check=True,
    )
    nu, share = done.stdout.split()
    assert nu == "23"
    assert Path(share) == site / "wholebody" / "_share"
