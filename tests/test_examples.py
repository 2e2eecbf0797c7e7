"""Every script of ``examples/`` runs as a user runs it (``python examples/NAME.py``) and
exits 0: each asserts what it claims. Each is short (< 80 lines) and says what it shows."""

from __future__ import annotations

import ast
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

import wholebody
from wholebody.robot.urdf import example_robot_data_share

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_ROOT = Path(wholebody.__file__).resolve().parents[1]  # (site-packages, or src)
EXAMPLES = ROOT / "examples"
ROBOTS = pytest.mark.skipif(
    example_robot_data_share() is None,
    reason="needs the robots extra (example-robot-data): pip install '.[robots]'",
)
SIM = pytest.mark.skipif(
    importlib.util.find_spec("mujoco") is None,
    reason="needs the sim extra (MuJoCo): pip install '.[sim]'",
)
SLOW = pytest.mark.slow  # each example is a new process: 2-5 s; three stay in the fast subset
CASES = {
    "quickstart": [],
    "custom_task": [],
    "projection_vs_hqp": [SLOW],
    "closed_chain": [SLOW],
    "dmp_obstacle": [],
    "human_arm_angle": [SLOW],
    "reachability_map": [SLOW],
    "small_sweep": [SLOW],
    "tiago_base_reach": [ROBOTS, SLOW],
    "panda_box": [ROBOTS, SLOW],
    "ur5_joint_limit": [ROBOTS, SLOW],
    "mujoco_physics": [SIM, SLOW],
    "torque_standing": [ROBOTS, SIM, SLOW],
}


def _run(name: str, args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``python examples/NAME.py ARGS`` in ``cwd``, on the wholebody this suite tests (the
    installed package, or the checkout's ``src``: the same compiled kernels' cache, so that
    no example compiles them again), its temporary files (a replay page) in ``cwd``."""
    env = {
        **os.environ,
        "TMPDIR": str(cwd),
        "PYTHONPATH": os.pathsep.join([str(PACKAGE_ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.run(
        [sys.executable, str(EXAMPLES / f"{name}.py"), *args],
        cwd=cwd,
        env=env,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=600,
    )


ARGS = {"small_sweep": ["--out", "sweep"]}  # (relative to the test's own directory)


def test_every_example_is_listed_short_and_documented():
    found = {p.stem for p in EXAMPLES.glob("*.py")}
    assert found == set(CASES), f"examples not tested: {found - set(CASES)}"
    assert len(found) >= 12
    for path in EXAMPLES.glob("*.py"):
        lines = path.read_text().splitlines()
        assert len(lines) < 80, f"{path.name}: {len(lines)} lines (at most 79)"
        doc = ast.get_docstring(ast.parse(path.read_text()))
        assert doc and f"python examples/{path.name}" in doc, f"{path.name}: no usage docstring"


@pytest.mark.parametrize(
    "name", [pytest.param(name, marks=marks, id=name) for name, marks in CASES.items()]
)
def test_example_runs_and_its_claims_hold(name, tmp_path):
    out = _run(name, ARGS.get(name, []), tmp_path)
    assert out.returncode == 0, f"{name} failed:\n{out.stdout}\n{out.stderr}"
    assert out.stdout.strip(), f"{name} printed no result"


@pytest.mark.slow
def test_viz_saves_the_replay_page_without_a_terminal(tmp_path):
    """``--viz`` with no terminal on standard input: the page is written and the script ends
    (the viewer waits for Enter only on a terminal)."""
    out = _run("closed_chain", ["--viz"], tmp_path)
    assert out.returncode == 0, out.stderr
    page = next(line for line in out.stdout.splitlines() if line.startswith("replay: "))
    path = Path(page.split()[1])
    assert path.is_file() and path.stat().st_size > 10_000 and tmp_path in path.parents
