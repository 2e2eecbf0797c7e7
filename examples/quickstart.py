"""Quickstart: the humanoid's right hand 10 cm forward, right and up, above a posture task.

The README's "Quickstart": a hand task above a posture task, joint position and velocity
limits, and the control loop, one `Controller.step` call a step (100 Hz for 2 s).

    python examples/quickstart.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("mobile_humanoid")
hand = wb.FrameTask(robot, "right_tool", kp=10.0)  # 6-D pose, 1/s
stack = wb.Stack(
    robot,
    [[hand], [wb.PostureTask(robot)]],  # hands above posture
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
q = robot.home()
goal = robot.frame_pose(q, "right_tool")
goal[:3, 3] += (0.1, -0.1, 0.1)  # 10 cm forward, right and up (m, world)
hand.set_target(goal)
controller = wb.Controller(robot, stack, wb.ProjectionSolver(), dt=0.01)
qs = [q]
for _ in range(200):  # 2 s at 100 Hz
    u = controller.step(q)  # actuated velocities (rad/s, m/s) to send to the robot
    q = controller.q_next.copy()  # where u takes it in dt (exact integration)
    qs.append(q)

miss = np.linalg.norm(robot.frame_pose(q, "right_tool")[:3, 3] - goal[:3, 3])
print(controller.result.report())
print(f"the hand ends {miss * 1e3:.4f} mm from its goal")
assert miss < 1e-4, f"the hand should end within 0.1 mm of its goal, it is {miss * 1e3:.3f} mm off"

if args.viz:
    from wholebody.viz import replay

    replay(
        robot,
        np.arange(len(qs)) * 0.01,
        np.array(qs),
        draw=lambda scene: scene.marker("goal", goal[:3, 3]),
    )
