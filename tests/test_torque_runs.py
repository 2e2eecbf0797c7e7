"""Torque control on MuJoCo: the plant's torque mode and velocity read-out, pushes, and the
scenarios run with ``--backend dynamics`` (wholebody.scenarios.torque_run)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.errors import ConfigError, ModelError
from wholebody.robot.sim import wheel_dofs
from wholebody.scenarios import load_scenario, run_scenario
from wholebody.scenarios.torque_run import _pusher

pytest.importorskip("mujoco")
from wholebody.sim import MujocoPlant


@pytest.mark.parametrize("name", ["talos_full", "mobile_humanoid"])
def test_the_plants_velocity_is_pinocchios(name):
    """``velocity()`` in Pinocchio's frames: ``difference(q_k, q_k+1) / dt`` (MuJoCo's
    semi-implicit step moves q by the new velocity) over a step under some torque; a
    wheeled base's wheels at the speeds that roll its root's motion (``v_root = B u``)."""
    robot = wb.load_robot(name)
    plant = MujocoPlant(robot)
    q = robot.home()
    plant.reset(q)
    force = np.zeros(robot.nv)
    force[6 if robot.base.floating else 0 :] = 5.0
    for _ in range(3):
        q1 = plant.torque_step(q, force, 0.001)
        v = plant.velocity()
        fd = pin.difference(robot.model, q, q1) / 0.001
        wheels = wheel_dofs(robot)
        rest = np.setdiff1d(np.arange(robot.nv), wheels)
        assert np.abs(fd - v)[rest].max() < 1e-6 * (1 + np.abs(v).max())
        if wheels:
            assert np.allclose(robot.base.matrix @ v[wheels], v[:3], atol=1e-9)
        q = q1


def test_gravity_torque_holds_an_arm_and_excess_is_clamped_and_logged():
    robot = wb.load_robot("panda")
    plant = MujocoPlant(robot)
    q0 = robot.home()
    plant.reset(q0)
    data, q = robot.model.createData(), q0
    for _ in range(300):
        tau = pin.rnea(robot.model, data, q, np.zeros(robot.nv), np.zeros(robot.nv))
        q = plant.torque_step(q, tau, 0.001)
    assert np.abs(pin.difference(robot.model, q0, q)).max() < 2e-3
    assert not np.any(plant.log.saturated)
    big = np.zeros(robot.nv)
    big[1] = 10 * plant.world.effort[1]
    plant.torque_step(q, big, 0.001)
    assert plant.log.saturated[-1][1] and plant.log.torque_peak[-1][1] <= plant.world.effort[1]


def test_a_floating_base_has_no_motor():
    robot = wb.load_robot("talos_full")
    plant = MujocoPlant(robot)
    q = robot.home()
    plant.reset(q)
    force = np.zeros(robot.nv)
    force[2] = 100.0
    with pytest.raises(ModelError, match="no motor"):
        plant.torque_step(q, force, 0.001)


def test_a_push_acts_on_its_body_only_while_it_lasts():
    spec = load_scenario("tasks/talos_stand_reach.toml")
    robot = wb.load_robot("talos_full")
    plant = MujocoPlant(robot)
    plant.reset(robot.home())
    push = _pusher(spec, robot, plant, 0.0)
    p = spec.torque.pushes[0]
    body = plant.body_of(p.frame)
    push(p.start + 0.5 * p.duration)
    assert np.allclose(plant.data.xfrc_applied[body, :3], p.force)
    assert np.flatnonzero(np.abs(plant.data.xfrc_applied).sum(axis=1)).tolist() == [body]
    push(p.start + p.duration)
    assert not plant.data.xfrc_applied.any()
    assert _pusher(spec, robot, None, 0.0) is None  # a kinematic run: nothing to push


def test_a_floating_base_needs_contacts_at_the_torque_level(tmp_path):
    text = Path("tasks/talos_stand_reach.toml").read_text()
    cut = text.split("[torque.contacts.left_sole_link]")[0]
    cut += text[text.index("[[torque.pushes]]") :]
    path = tmp_path / "no_feet.toml"
    path.write_text(cut)
    with pytest.raises(ConfigError, match="contacts"):
        run_scenario(load_scenario(path), duration_scale=0.01)


@pytest.mark.slow
def test_talos_stands_reaches_and_recovers_from_a_push_under_torque_control():
    """The issue's targets: both hands reach (within 5 mm), the feet slip at most 1 mm, the
    CoP stays 2 cm inside the soles' edges, every bound holds, and it does not fall, through
    the push."""
    run = run_scenario(load_scenario("tasks/talos_stand_reach.toml"), sim="mujoco")
    m = run.metrics
    assert m["backend"] == "dynamics" and not m["stopped"]
    assert not m["fell"]
    assert m["foot_slip_max_m_all"] < 1e-3
    assert m["cop_margin_min_m"] > 0.019
    assert m["violation_max"] < 1e-6
    assert m["com_after_push_m"] < 0.01
    for hand in ("left", "right"):
        err = run.log.frame_positions[hand][-1] - run.log.reference_positions[hand][-1]
        assert np.linalg.norm(err) < 5e-3
    assert run.torque is not None and run.torque["tau"].shape == (len(run.log), 36)
