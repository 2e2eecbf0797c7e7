"""The human arm angle: the elbow held where people hold theirs for the same wrist.

The same 25 cm reach with the paper's stack twice: with its arm-energy spring (the default),
and with the human-like preset (`wholebody.presets.HUMAN_LIKE`: a human-arm-angle task level
below the hands, which drives the arm angle to `alpha_h(wrist)`, a model learned from
people's reaching, and the waist dear in the velocity metric). At the end the preset's arm
angle is the closer to people's.

    python examples/human_arm_angle.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb
from wholebody.arm import default_arm_angle_model
from wholebody.presets import HUMAN_LIKE

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the human-like run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("mobile_humanoid")
q0 = robot.home()
start = robot.frame_pose(q0, "right_tool")
goal = start.copy()
goal[:3, 3] += (0.25, 0.0, 0.2)  # 25 cm forward, 20 cm up (m, world)
people = wb.HumanArmAngleTask(robot, "right", default_arm_angle_model())  # a yardstick only
gaps = {}
for name, weights in [
    ("spring", wb.PaperWeights()),
    ("human arm angle", HUMAN_LIKE),
]:
    hand = wb.FrameTask(robot, "right_tool", kp=20.0, ki=5.0)
    stack = wb.paper_stack(robot, [hand], weights=weights)  # hands, (arm angles,) H, limits
    reference = wb.MinimumJerkTrajectory(start, goal, 2.0)
    log = wb.Controller(
        robot, stack, wb.ProjectionSolver(), dt=0.01, references={hand: reference}
    ).run(q0, 2.5)
    state = robot.update(log.meta["final_q"])
    gaps[name] = abs(people.error(state)[0])  # |alpha - alpha_h| (rad)
    miss = np.linalg.norm(state.position(hand.frame) - goal[:3, 3])
    print(
        f"{name}: the arm angle ends {np.degrees(gaps[name]):.1f} deg from people's; "
        f"the hand {miss * 1e3:.3f} mm from its goal"
    )
    assert miss < 1e-3, f"{name}: the hand should reach its goal, {miss * 1e3:.2f} mm off"

assert gaps["human arm angle"] < gaps["spring"], "the task should bring the arm closer to people's"
assert gaps["human arm angle"] < np.radians(2.0), "the task should meet people's arm angle"

if args.viz:
    from wholebody.viz import replay

    replay(robot, log.t, log.q, draw=lambda scene: scene.marker("goal", goal[:3, 3]))
