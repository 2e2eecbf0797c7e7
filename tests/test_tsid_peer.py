"""TSID as a peer in its own venv (benchmarks/tsid_peer.py, benchmarks/peers/tsid/).

The problem is built from talos_stand.py's defaults and robots/talos_full/robot.toml; a
missing venv gives an error naming the setup command. With the venv made (setup.sh), a short
run keeps both feet in contact and tracks the CoM. No timing here.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest


def _load_tsid_peer():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "tsid_peer.py"
    if "wholebody_bench_tsid_peer" in sys.modules:
        return sys.modules["wholebody_bench_tsid_peer"]
    spec = importlib.util.spec_from_file_location("wholebody_bench_tsid_peer", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


tsid_peer = _load_tsid_peer()


def test_default_problem_reads_robot_toml():
    problem = tsid_peer.default_problem(steps=100)
    assert problem["steps"] == 100
    assert problem["locked"] == {"gripper_*": 0.0}
    assert problem["q0"]["leg_left_4_joint"] == pytest.approx(0.859395)
    assert (problem["lx"], problem["ly"], problem["mu"]) == (0.1, 0.065, 0.3)
    assert (problem["fmin"], problem["fmax"]) == (5.0, 1500.0)
    with pytest.raises(ValueError, match="unknown problem keys"):
        tsid_peer.default_problem(bogus=1)


def test_missing_venv_names_the_setup_command(monkeypatch):
    monkeypatch.setattr(tsid_peer, "VENV_PYTHON", Path("/nonexistent/bin/python"))
    with pytest.raises(tsid_peer.TsidPeerError, match=r"benchmarks/peers/tsid/setup\.sh"):
        tsid_peer.run_tsid(tsid_peer.default_problem())


needs_venv = pytest.mark.skipif(
    not tsid_peer.VENV_PYTHON.exists(),
    reason="TSID's venv is not made (bash benchmarks/peers/tsid/setup.sh)",
)


@needs_venv
def test_short_run_holds_the_feet():
    result = tsid_peer.run_tsid(tsid_peer.default_problem(steps=200))
    assert result["versions"]["tsid"] == "1.10.0"
    assert (result["nv"], result["qp"]["n_var"]) == (36, 60)  # 36 + 4 corners x 3 x 2 feet
    assert result["solver_failures"] == 0
    assert result["com_error_m"]["max"] < 0.01
    for foot in result["feet_drift"].values():
        assert foot["translation_m"] < 1e-4
    assert result["cop_margin_min_m"] > -1e-9  # the CoP never leaves a sole
    assert result["torque_ratio_max"] <= 1.0 + 1e-9


@needs_venv
def test_bad_problem_fails_with_the_scripts_message():
    with pytest.raises(tsid_peer.TsidPeerError, match=r"fmax = 1\.0 is below fmin"):
        tsid_peer.run_tsid({"fmax": 1.0})
