"""What the controller reads: a sensor's noise and delay (wholebody.control.JointSensor) on a
plant, and the controller's latency compensation that brings a late measurement to the
present (issue 32, item 9)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wholebody import ConfigError, WholebodyError
from wholebody.control import Controller, JointSensor
from wholebody.planning.trajectory import MinimumJerkTrajectory
from wholebody.presets import paper_stack
from wholebody.resources import tasks_dir
from wholebody.scenarios import load_scenario, run_scenario
from wholebody.solvers import ProjectionSolver
from wholebody.tasks import FrameTask

MM = 1e-3


def _walk(robot, steps: int, seed: int = 0) -> list[np.ndarray]:
    """``steps + 1`` configurations, each a random 10 ms move from the last."""
    rng = np.random.default_rng(seed)
    qs = [robot.home()]
    for _ in range(steps):
        qs.append(robot.integrate(qs[-1], rng.uniform(-0.5, 0.5, robot.nu), 0.01))
    return qs


@pytest.mark.parametrize("delay", [0, 1, 3])
def test_a_sensor_delays_by_exactly_n_periods(humanoid, delay):
    """Read after period j, the sensor gives the configuration of ``delay`` periods before
    (the start one before the run): the same numbers, bit for bit."""
    qs = _walk(humanoid, 8)
    readout = JointSensor(delay=delay).start(humanoid, qs[0])
    for j in range(1, len(qs)):
        seen = readout.read(qs[j])
        assert np.array_equal(seen, qs[max(j - delay, 0)]), j
        assert seen is not qs[max(j - delay, 0)]  # a new array: the caller may keep it


def test_the_noise_is_bounded_uniform_and_seeded(humanoid):
    """Every encoder (actuated joint) off by at most the amplitude, spread over all of it
    (uniform), the same draws for the same seed after a new start, other draws for another
    seed; with a delay, the noise is on the delayed configuration."""
    a = 1e-4
    qs = _walk(humanoid, 400)
    base = len(humanoid.base.actuators)

    def errors(sensor: JointSensor) -> np.ndarray:
        readout = sensor.start(humanoid, qs[0])
        out = []
        for j in range(1, len(qs)):
            seen = readout.read(qs[j])
            truth = qs[max(j - sensor.delay, 0)]
            out.append(
                humanoid.joint_positions(seen)[base:] - humanoid.joint_positions(truth)[base:]
            )
        return np.array(out)

    e = errors(JointSensor(a, seed=7))
    assert np.abs(e).max() <= a * (1 + 1e-9)
    assert np.abs(e).max() > 0.99 * a and abs(e.mean()) < 0.05 * a
    assert np.abs(e).mean() == pytest.approx(a / 2, rel=0.05)  # U[-a, a]: E|e| = a / 2
    assert np.array_equal(e, errors(JointSensor(a, seed=7)))
    assert not np.array_equal(e, errors(JointSensor(a, seed=8)))
    delayed = errors(JointSensor(a, delay=2, seed=7))
    assert np.abs(delayed).max() <= a * (1 + 1e-9) and np.abs(delayed).max() > 0.99 * a


def test_bad_sensor_and_latency_settings_are_named(humanoid):
    for kwargs, part in (
        ({"noise": -1e-4}, "noise"),
        ({"noise": float("nan")}, "noise"),
        ({"delay": 1.5}, "delay"),
        ({"delay": True}, "delay"),
        ({"seed": -1}, "seed"),
    ):
        with pytest.raises(ConfigError, match=f"sensor {part}"):
            JointSensor(**kwargs)
    assert JointSensor().exact and not JointSensor(delay=1).exact
    hand = FrameTask(humanoid, "right_tool")
    stack = paper_stack(humanoid, [hand], stiffness=0.1)
    with pytest.raises(WholebodyError, match="latency must be a whole number"):
        Controller(humanoid, stack, ProjectionSolver(), dt=0.01, latency=-1)
    with pytest.raises(WholebodyError, match="a run without a plant integrates exactly"):
        Controller(humanoid, stack, ProjectionSolver(), dt=0.01, latency=1).run(
            humanoid.home(), 0.05
        )
    spec = load_scenario(tasks_dir() / "coordinated_carry.toml")
    with pytest.raises(ConfigError, match="needs sim='mujoco'"):
        run_scenario(spec, sensor=JointSensor(1e-4, 1), duration_scale=0.01)


class _LatePlant:
    """Exact integration, read through a sensor: what a delayed encoder would give."""

    stop_reason = None

    def __init__(self, robot, sensor: JointSensor, q0: np.ndarray) -> None:
        self.robot, self.q = robot, q0.copy()
        self.readout = sensor.start(robot, q0)

    def step(self, q, u, dt):
        self.q = self.robot.integrate(self.q, u, dt)
        return self.readout.read(self.q)


def _reach(robot, plant=None, latency: int = 0) -> Controller:
    hand = FrameTask(robot, "right_tool", kp=20.0, ki=5.0)
    start = robot.frame_pose(robot.home(), hand.frame)
    goal = start.copy()
    goal[:3, 3] += (0.25, -0.1, 0.15)
    stack = paper_stack(robot, [hand], stiffness=0.1)
    return Controller(
        robot,
        stack,
        ProjectionSolver(),
        dt=0.01,
        plant=plant,
        latency=latency,
        references={hand: MinimumJerkTrajectory(start, goal, 0.8)},
    )


@pytest.mark.parametrize("delay", [1, 3])
def test_latency_brings_a_late_measurement_to_the_present(humanoid, delay):
    """On a plant that moves exactly as commanded and is read ``delay`` periods late, the
    controller that knows its latency computes every step at the true configuration: its run
    is the undelayed run (to rounding). Without it the hand runs ahead of its reference."""
    q0 = humanoid.home()
    plain = _reach(humanoid).run(q0, 1.0)
    late = _LatePlant(humanoid, JointSensor(delay=delay), q0)
    compensated = _reach(humanoid, late, latency=delay).run(q0, 1.0)
    np.testing.assert_allclose(compensated.q, plain.q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(compensated.u, plain.u, rtol=0, atol=1e-9)
    np.testing.assert_allclose(late.q, plain.meta["final_q"], rtol=0, atol=1e-9)
    stale = _LatePlant(humanoid, JointSensor(delay=delay), q0)
    _reach(humanoid, stale, latency=0).run(q0, 1.0)
    assert np.abs(stale.q - late.q).max() > 1e-4  # a different motion without the predictor


mujoco = pytest.importorskip("mujoco")
from wholebody.sim import MujocoPlant  # noqa: E402


def test_the_plant_reads_through_its_sensor(humanoid):
    """The plant returns its configuration of ``delay`` periods before, perturbed; it keeps
    the true one in its log, takes back what it returned, and a reset starts the same
    draws again."""
    delay, a = 2, 1e-4
    plant = MujocoPlant(humanoid, sensor=JointSensor(a, delay, seed=3))
    base = len(humanoid.base.actuators)
    u = np.zeros(humanoid.nu)
    u[base:] = 0.2

    def run() -> list[np.ndarray]:
        plant.reset(humanoid.home())
        q, seen = humanoid.home(), []
        for _ in range(6):
            q = plant.step(q, u, 0.01)  # what it gave back: accepted
            seen.append(q)
        return seen

    seen = run()
    truth = [*plant.log.configuration, plant.configuration()]  # at each period's start, end
    for j, q in enumerate(seen):
        e = (
            humanoid.joint_positions(q)[base:]
            - humanoid.joint_positions(truth[max(j + 1 - delay, 0)])[base:]
        )
        assert np.abs(e).max() <= a * (1 + 1e-9) and np.abs(e).max() > 0, j
    assert (
        np.abs(humanoid.joint_positions(truth[-1]) - humanoid.joint_positions(seen[-1])).max()
        > 1e-3
    )
    assert all(np.array_equal(x, y) for x, y in zip(seen, run(), strict=True))


@pytest.mark.slow
def test_a_physics_carry_with_noise_and_delay_still_tracks():
    """The coordinated carry under MuJoCo, its joints read with +-1e-4 rad of noise and one
    period (10 ms) late: the true hands within 5 mm of their references at every step, the
    closed chain within 0.5 mm, the run to its end (measured: 2.96 mm, 0.25 mm)."""
    spec = load_scenario(tasks_dir() / "coordinated_carry.toml")
    run = run_scenario(spec, sim="mujoco", sensor=JointSensor(1e-4, 1))
    m = run.metrics
    assert m["stopped"] is None
    assert m["sensor"] == {
        "noise_rad_or_m": 1e-4,
        "delay_periods": 1,
        "seed": 0,
        "latency_compensated_periods": 1,
    }
    assert max(m["true_max_tracking_error_m"].values()) <= 5 * MM, m["true_max_tracking_error_m"]
    assert m["true_closed_chain_error_max_m"] <= 0.5 * MM
    assert run.physics["configuration"].shape == run.log.q.shape
    assert json.dumps(m["sensor"])  # plain data in metrics.json


def test_the_cli_takes_a_sensor_only_with_physics(tmp_path, capsys):
    from wholebody.cli import main

    assert main(["run", "coordinated_carry", "--sensor-delay", "1", "--out", str(tmp_path)]) == 2
    assert "add --sim mujoco" in capsys.readouterr().err
    assert (
        main(
            [
                "run",
                "coordinated_carry",
                "--sim",
                "mujoco",
                "--sensor-noise",
                "-1",
                "--out",
                str(tmp_path),
            ]
        )
        == 2
    )
    assert "sensor noise must be a finite number >= 0" in capsys.readouterr().err
