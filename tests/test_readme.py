"""The Python examples of the README and the guides (``docs/``): each runs on its own (a
fresh namespace, as a reader would paste it) and prints what it shows."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import numpy as np
import pytest

from wholebody.arm import arm_angle

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
NAMED = [
    (f"{page.relative_to(ROOT)} python block {k + 1}", code)
    for page in PAGES
    for k, code in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S))
]
BLOCKS = [code for _, code in NAMED]


def run_block(code: str, name: str) -> tuple[dict, str]:
    namespace: dict = {"__name__": "__readme__"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, name, "exec"), namespace)
    return namespace, out.getvalue()


SLOW_PAGES = ("docs/guides/physics.md",)  # (a MuJoCo run: in the full suite only)


@pytest.mark.parametrize(
    "index",
    [
        pytest.param(k, marks=pytest.mark.slow) if name.startswith(SLOW_PAGES) else k
        for k, (name, _) in enumerate(NAMED)
    ],
)
def test_a_readme_example_runs_on_its_own_and_prints(index, monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    name, code = NAMED[index]
    _, printed = run_block(code, name)
    assert printed.strip(), f"{name} prints nothing"


@pytest.mark.slow
def test_the_examples_do_what_they_say(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    found = {
        "quickstart": False,
        "reach": False,
        "dmp": False,
        "recovery": False,
        "arm angle": False,
        "collision": False,
    }
    for name, code in NAMED:
        ns, _ = run_block(code, name)
        if "hand.set_target(goal)" in code:  # the quickstart reaches its goal
            q, goal, robot = ns["q"], ns["goal"], ns["robot"]
            assert np.linalg.norm(robot.frame_pose(q, "right_tool")[:3, 3] - goal[:3, 3]) < 1e-3
            found["quickstart"] = True
        if "the paper's single-arm reach" in code:
            log, goal = ns["log"], ns["goal"]
            assert abs(log.frame_positions["right_tool"][-1] - goal[:3, 3]).max() < 1e-3
            found["reach"] = True
        if "DMP.fit" in code:
            assert ns["path"].positions.shape == (160, 3)
            found["dmp"] = True
        if 'run.meta["retreats"]' in code:  # out of its local minimum by default, one retreat
            assert len(ns["run"].meta["retreats"]) == 1 and ns["miss"] < 1e-3
            found["recovery"] = True
        if "human_arm_angle_kp" in code:  # the elbow where people hold it, the hand reached
            robot, state, arm = ns["robot"], ns["state"], ns["robot"].arm("right")
            S, E, W = (state.position(f) for f in (arm.shoulder, arm.elbow, arm.wrist))
            assert abs(arm_angle(S, E, W, -1.0) - ns["alpha_h"]) < 0.01
            hand = ns["log"].frame_positions["right_tool"][-1]
            assert np.linalg.norm(hand - ns["goal"][:3, 3]) < 1e-3
            found["arm angle"] = True
        if "wb.CollisionAvoidance" in code:  # the hand passes the ball 1 cm off, not through
            assert ns["collision"].safety <= ns["closest"] < 0.02
            found["collision"] = True
    assert all(found.values()), found
