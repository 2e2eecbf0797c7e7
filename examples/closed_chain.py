"""Both hands hold a virtual panel and carry it 15 cm up while turning it 0.3 rad.

The closed chain is a task of its own, a level above the hands: the right hand's pose in the
left hand's frame (`RelativeFrameTask`) held where it was at the grasp. The left hand
follows the panel's reference; the right one follows through the chain, never the other way.

    python examples/closed_chain.py [--viz]
"""

import argparse

import numpy as np
import pinocchio as pin

import wholebody as wb

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("mobile_humanoid")
q0 = robot.home()
left, right = (robot.frame_pose(q0, f) for f in ("left_tool", "right_tool"))
chain = wb.RelativeFrameTask(robot, "left_tool", "right_tool", name="chain", kp=20.0)
chain.set_target(np.linalg.inv(left) @ right)  # the grasp: right hand in the left hand's frame
hand = wb.FrameTask(robot, "left_tool", kp=20.0, ki=5.0)
stack = wb.Stack(
    robot,
    [[chain], [hand], [wb.PostureTask(robot)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
panel = np.eye(4)
panel[:3, 3] = (left[:3, 3] + right[:3, 3]) / 2  # the panel between the hands
moved = np.eye(4)
moved[:3, :3] = pin.exp3(np.array([0.0, 0.0, 0.3]))  # turned 0.3 rad about the vertical
moved[:3, 3] = panel[:3, 3] + (0.0, 0.0, 0.15)  # and lifted 15 cm
goal = moved @ np.linalg.inv(panel) @ left  # where the left hand carries it
reference = wb.MinimumJerkTrajectory(left, goal, 3.0)
controller = wb.Controller(
    robot, stack, wb.ProjectionSolver(), dt=0.01, references={hand: reference}
)
log = controller.run(q0, 4.0)

chain_error = np.linalg.norm(log.task_errors["chain"][:, :3], axis=1).max()  # m
q = np.asarray(log.meta["final_q"])
miss = np.linalg.norm(robot.frame_pose(q, "left_tool")[:3, 3] - goal[:3, 3])
print(
    f"the closed chain's largest error {chain_error * 1e3:.4f} mm; "
    f"the left hand ends {miss * 1e3:.4f} mm from its goal"
)
assert chain_error < 1e-4, (
    f"the chain should hold within 0.1 mm, it erred {chain_error * 1e3:.3f} mm"
)
assert miss < 1e-3, f"the panel should reach its goal, the hand is {miss * 1e3:.2f} mm off"

if args.viz:
    from wholebody.viz import replay

    panels = np.array(
        [robot.frame_pose(x, "left_tool") @ np.linalg.inv(left) @ panel for x in log.q]
    )
    draw = lambda scene: scene.box("panel", (0.3, 1.0, 0.02), panel)  # noqa: E731
    replay(robot, log.t, log.q, draw=draw, extra={"scene/props/panel": panels})
