"""wholebody and its peers (pink, mink, placo) solve the same problem (benchmarks/peers.py).

For each installed peer, over a short stretch of the benchmark's shared reference, the hands of
the peer and of wholebody (HQP, the exact QP solution) agree to 0.1 mm at every step, for the
single weighted QP and for the two-level hierarchy; and one step from the home posture gives
the same base twist and joint speeds up to the peers' error conventions. No timing here.
"""

from __future__ import annotations

import importlib.util
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

STEPS = 50
TOLERANCE = 1e-4  # m: 0.1 mm
# One step from home: pink and mink use the SE(3) log in the hand frame (it couples the
# rotation and translation errors), wholebody and placo [p_d - p; log3] in world axes; at the
# reference's peak step the speeds differ by ~2.5e-3 of the largest one (placo: ~1e-7).
VELOCITY_TOLERANCE = {"pink": 1e-2, "mink": 1e-2, "placo": 1e-5, "wholebody": 1e-8}


def _load_peers():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "peers.py"
    if "wholebody_bench_peers" in sys.modules:
        return sys.modules["wholebody_bench_peers"]
    spec = importlib.util.spec_from_file_location("wholebody_bench_peers", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses resolve the module by name
    spec.loader.exec_module(module)
    return module


peers = _load_peers()


@pytest.fixture(scope="module")
def setup():
    return peers.make_setup()


@pytest.fixture(scope="module")
def reference(setup):
    """wholebody's HQP run per problem: hand positions per step, one-step velocity."""
    out = {}
    for problem in (peers.SINGLE, peers.HIERARCHY):
        case = peers.WholebodyCase(setup, "daqp", problem)
        out[problem] = (_hands(setup, case), peers.one_step(setup, case))
    return out


def _hands(setup, case) -> np.ndarray:
    case.reset()
    path = np.empty((STEPS, 2, 3))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Converted matrix")
        for k in range(STEPS):
            case.step(setup.targets(k))
            path[k] = case.hand_positions()
    return path


def _skip_missing(library: str) -> None:
    if library == "wholebody":
        return
    module = {"pink": "pink", "mink": "mink", "placo": "placo"}[library]
    pytest.importorskip(module, reason=f"{library} is not installed (bench extra)")
    if library == "mink":
        pytest.importorskip("mujoco", reason="mink needs mujoco")


CASES = [
    ("pink", "daqp"),
    ("pink", "proxqp"),
    ("mink", "daqp"),
    ("placo", "eiquadprog"),
]


@pytest.mark.parametrize("problem", [peers.SINGLE, peers.HIERARCHY])
@pytest.mark.parametrize(("library", "backend"), CASES)
def test_hands_agree(setup, reference, library, backend, problem):
    _skip_missing(library)
    if backend == "proxqp":
        pytest.importorskip("proxsuite")
    case = peers.build_case(setup, library, backend, problem)
    ours, u_ref = reference[problem]
    theirs = _hands(setup, case)
    dev = np.linalg.norm(theirs - ours, axis=2)
    assert dev.max() <= TOLERANCE, f"{case.name}: hands differ by {dev.max() * 1e3:.4f} mm"
    # the reference really moves the hands (the agreement is not trivial)
    targets = np.array([[T[:3, 3] for T in setup.targets(k)] for k in range(STEPS)])
    assert np.linalg.norm(targets[-1] - targets[0], axis=1).min() > 5e-3
    # the same problem: one step from home gives the same base twist and joint speeds
    u = peers.one_step(setup, case)
    rel = np.abs(u - u_ref).max() / np.abs(u_ref).max()
    assert rel <= VELOCITY_TOLERANCE[library], f"{case.name}: velocities differ by {rel:.2e}"


@pytest.mark.parametrize("problem", [peers.SINGLE, peers.HIERARCHY])
def test_projection_matches_hqp(setup, reference, problem):
    """No bound is active along the reference: both backends solve the same least squares
    (the single level has 35 rows for 23 columns: no spurious damping)."""
    case = peers.WholebodyCase(setup, "projection", problem)
    ours, u_ref = reference[problem]
    dev = np.linalg.norm(_hands(setup, case) - ours, axis=2)
    assert dev.max() <= TOLERANCE
    u = peers.one_step(setup, case)
    assert np.abs(u - u_ref).max() <= VELOCITY_TOLERANCE["wholebody"] * np.abs(u_ref).max()


def test_base_cost_is_the_wheel_regularisation(setup):
    """The peers' base-twist cost equals wholebody's posture cost on the wheel speeds at the
    least-squares wheel speeds ``B^+ v``, for any base twist."""
    B = setup.robot.base.matrix
    rng = np.random.default_rng(0)
    for _ in range(5):
        v = rng.normal(size=3)
        wheels = np.linalg.pinv(B) @ v
        assert np.isclose(peers.W_POSTURE * wheels @ wheels, v @ (setup.base_cost * v))


def test_missing_peer_is_reported(monkeypatch):
    monkeypatch.setitem(peers.PEERS, "pink", ("wholebody_no_such_module", peers.PinkCase))
    lines = []
    cases = peers.build_cases(peers.make_setup(), say=lines.append)
    assert any(line.startswith("skipped pink: not installed") for line in lines)
    assert all(c.library != "pink" for c in cases)


@pytest.mark.parametrize("problem", [peers.SINGLE, peers.HIERARCHY])
@pytest.mark.parametrize("name", ["tiago_dual", "talos_upper"])
def test_real_robot_pink_solves_the_same_problem(name, problem):
    """On a robot from example-robot-data (control_step.py's real-robot rows), pink on
    wholebody's model and wholebody's HQP solve the same problem: hands within 0.1 mm over
    STEPS steps of the robot's reference, one step from home giving the same base twist and
    joint speeds up to pink's error convention. On TIAGo++ the differential base moves in
    both, without lateral velocity in pink (the equality that stands for the drive)."""
    pytest.importorskip("pink", reason="pink is not installed (bench extra)")
    why = peers.robot_available(name)
    if why is not None:
        pytest.skip(f"{name}: {why}")
    setup = peers.make_robot_setup(name)
    ours = peers.WholebodyCase(setup, "daqp", problem)
    theirs = peers.RobotPinkCase(setup, "daqp", problem)
    dev = np.linalg.norm(_hands(setup, theirs) - _hands(setup, ours), axis=2)
    assert dev.max() <= TOLERANCE, f"{name}: hands differ by {dev.max() * 1e3:.4f} mm"
    targets = np.array([[T[:3, 3] for T in setup.targets(k)] for k in range(STEPS)])
    assert np.linalg.norm(targets[-1] - targets[0], axis=1).min() > 2e-3  # they move
    u_ref, u = peers.one_step(setup, ours), peers.one_step(setup, theirs)
    assert np.abs(u - u_ref).max() <= VELOCITY_TOLERANCE["pink"] * np.abs(u_ref).max()
    if setup.mobile:
        assert np.abs(u_ref[0]) > 1e-3 * np.abs(u_ref).max()  # the base drives forward
        assert np.abs(u[1]) < 1e-12  # and never sideways in pink either
