"""A lower level stalled against the joint limits under a closed chain settles instead of
cycling (the HQP's stall damping), and the run metric that counts reversals of ``u``.

The setup (also ``benchmarks/limit_cycles.py``): both hands hold their relative pose on level
1, the right hand's pose task on level 2 is sent where the wrist and elbow cannot take it
while the chain holds; position and velocity limits. The exact cascade then alternates
between two answers every step at the velocity limits, the chain drifting off by a
millimetre; damped, the lower level's ``u`` decays and the chain holds.
"""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path

import numpy as np
import pytest

import wholebody as wb
from wholebody.control.metrics import (
    REVERSAL_THRESHOLD,
    closed_chain_error,
    limit_violations,
    summary,
    u_reversals,
)
from wholebody.errors import DataError, SolverError
from wholebody.robot.urdf import example_robot_data_share
from wholebody.solvers.hqp import STALL_DAMPING

DT = 0.01
ENGINES = ["daqp", pytest.param("proxsuite", marks=pytest.mark.slow)]  # (the other: slow)


def _load_limit_cycles():
    """``benchmarks/limit_cycles.py``, whose setup this file tests."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "limit_cycles.py"
    spec = importlib.util.spec_from_file_location("wholebody_bench_limit_cycles", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


limit_cycles = _load_limit_cycles()


def stalled_run(robot, solver, *, rotation, axis=(1.0, 0.0, 0.0), lift=0.05, duration=4.0):
    """The benchmark's run (the chain on level 1, the right hand on level 2 sent to its home
    pose turned by ``rotation`` rad about the world ``axis`` and lifted by ``lift`` m): the
    log and the controller."""
    return limit_cycles.stalled_run(
        robot,
        solver,
        rotation=rotation,
        axis=axis,
        shift=(0.0, 0.0, lift),
        duration=duration,
        dt=DT,
    )


def window(log, start, stop=None):
    """The steps from ``start`` to ``stop`` s (a mask)."""
    t = np.arange(len(log.u)) * DT
    return (t >= start - 1e-9) & (t < (np.inf if stop is None else stop) - 1e-9)


def assert_settles(log, stall, settled):
    """From ``stall`` s on: no reversal of u but for a stray one (a joint turning back; a
    cycle reverses at every step), the largest |u| of each half second no larger than the
    one before and halved by the end; the chain held within 1e-6 m from ``settled`` s on; no
    limit violated."""
    assert u_reversals(log.u[window(log, stall)]) <= 2
    end = log.u.shape[0] * DT
    peaks = [np.abs(log.u[window(log, t, t + 0.5)]).max() for t in np.arange(stall, end, 0.5)]
    assert all(b <= 1.05 * a + 1e-6 for a, b in itertools.pairwise(peaks))
    assert peaks[-1] <= 0.5 * peaks[0] + 1e-6
    assert closed_chain_error(log, "chain", window(log, settled)) < 1e-6
    assert limit_violations(log) == 0


# ---------------------------------------------------------------------- the metric
def test_u_reversals_counts_the_steps_where_a_velocity_changes_sign():
    small = 0.5 * REVERSAL_THRESHOLD
    u = np.array(
        [[1.0, 0.0], [-1.0, 0.0], [-1.0, small], [1.0, -small], [1.0, -small], [-2.0, 3.0]]
    )
    assert u_reversals(u) == 3  # steps 1, 3 and 5 (5: two joints at once)
    assert u_reversals(u, threshold=1.5) == 0  # (|u| of step 4 is 1 on the first joint)
    assert u_reversals(np.zeros((0, 3))) == 0
    with pytest.raises(DataError, match="steps, nu"):
        u_reversals(np.ones(4))


def test_the_run_metrics_report_u_reversals(humanoid):
    log, _ = stalled_run(humanoid, wb.HierarchicalQPSolver(), rotation=1.5, duration=0.5)
    assert summary(log)["u_reversals"] == u_reversals(log.u)


# ---------------------------------------------------------------------- the stall
def test_the_exact_cascade_cycles_on_the_stalled_lower_level(humanoid):
    """The premise: without the damping the setup is a limit cycle (a reversal at nearly
    every step, at the velocity limits, the chain a millimetre off)."""
    log, _ = stalled_run(humanoid, wb.HierarchicalQPSolver(stall_damping=0.0), rotation=1.5)
    stall = window(log, 2.0)
    assert u_reversals(log.u[stall]) > 0.9 * np.count_nonzero(stall)
    assert closed_chain_error(log, "chain", stall) > 1e-4


@pytest.mark.parametrize("engine", ENGINES)
def test_a_stalled_lower_level_settles_under_the_closed_chain(humanoid, engine):
    solver = wb.HierarchicalQPSolver(engine)
    log, controller = stalled_run(humanoid, solver, rotation=1.5)
    assert_settles(log, stall=2.0, settled=3.0)
    assert np.abs(log.u[-1]).max() < 0.2  # rad/s (25 and 2 rad/s, cycling, without)
    assert [task for _, task in controller.result.infeasible] == ["hand"]
    chain, hand = solver.levels  # (the last step's, read with the result)
    assert hand.damped and not chain.damped
    assert chain.residual < 1e-6  # (weighted) the chain met at the last step
    assert hand.residual > 0.1  # and the hand stalled


@pytest.mark.slow
@pytest.mark.skipif(example_robot_data_share() is None, reason="example-robot-data missing")
@pytest.mark.parametrize("engine", ENGINES)
def test_tiagos_stalled_hand_settles(engine):
    """TIAGo++'s wrists: the exact cascade cycles at their velocity limits (2.35 rad/s)."""
    tiago = wb.load_robot("tiago_dual")
    run = {
        mu: stalled_run(
            tiago,
            wb.HierarchicalQPSolver(engine, stall_damping=mu),
            rotation=-1.0,
            axis=(0.0, 0.0, 1.0),
            duration=3.0,
        )[0]
        for mu in (0.0, STALL_DAMPING)
    }
    assert u_reversals(run[0.0].u[window(run[0.0], 2.0)]) > 90
    assert_settles(run[STALL_DAMPING], stall=1.0, settled=2.0)
    assert np.abs(run[STALL_DAMPING].u[-1]).max() < 1e-2


# ---------------------------------------------------------------------- where it does not act
def test_a_met_lower_level_is_solved_exactly(humanoid):
    """A reachable target: the hand is met at every step, never damped, u bit for bit the
    exact cascade's."""
    logs = {}
    for mu in (0.0, STALL_DAMPING):
        solver = wb.HierarchicalQPSolver(stall_damping=mu)
        logs[mu], controller = stalled_run(
            humanoid, solver, rotation=0.05, lift=0.005, duration=1.0
        )
        assert not controller.result.infeasible
        assert not any(level.damped for level in solver.levels)
    np.testing.assert_array_equal(logs[0.0].u, logs[STALL_DAMPING].u)
    assert np.linalg.norm(logs[0.0].task_errors["hand"][-1]) < 1e-4


def test_the_first_level_is_never_damped(humanoid):
    """The hand alone on level 1, 2 m out of reach: unmet, solved exactly all the same."""
    hand = wb.FrameTask(humanoid, "right_tool", name="hand", kp=10.0)
    q0 = humanoid.home()
    goal = humanoid.frame_pose(q0, "right_tool")
    goal[:3, 3] += (0.0, 0.0, 2.0)
    hand.set_target(goal)
    logs = {}
    for mu in (0.0, STALL_DAMPING):
        solver = wb.HierarchicalQPSolver(stall_damping=mu)
        stack = wb.Stack(
            humanoid, [[hand]], [wb.JointPositionLimits(humanoid), wb.VelocityLimits(humanoid)]
        )
        controller = wb.Controller(humanoid, stack, solver, dt=DT, recovery=False)
        logs[mu] = controller.run(q0, 0.5)
        assert controller.result.infeasible and not solver.levels[0].damped
    np.testing.assert_array_equal(logs[0.0].u, logs[STALL_DAMPING].u)


def test_stall_damping_is_a_checked_setting():
    assert wb.HierarchicalQPSolver().stall_damping == STALL_DAMPING
    assert wb.HierarchicalQPSolver(stall_damping=0).stall_damping == 0.0
    for bad in (-0.1, float("nan"), "x"):
        with pytest.raises(SolverError, match="stall_damping"):
            wb.HierarchicalQPSolver(stall_damping=bad)
