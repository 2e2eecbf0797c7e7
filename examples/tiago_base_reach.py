"""TIAGo++ reaches 1.2 m forward with its right hand: out of the arm's reach, so the base drives.

The hand follows a 4 s minimum-jerk reference; the wheels are in `u` like any joint, cheap in
the metric (0.01), so the differential base rolls forward while the arm reaches. A second
task of the first level holds the base's heading: a differential base could otherwise turn
on the spot to swing the hand forward. Needs the `robots` extra (example-robot-data's
TIAGo++ URDF): `pip install ".[robots]"`.

    python examples/tiago_base_reach.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("tiago_dual")
hand = wb.FrameTask(robot, "arm_right_tool_link", kp=20.0, ki=5.0, orientation=False)
heading = wb.FrameTask(robot, robot.base_frame.name, name="heading", position=False, kp=5.0)
stack = wb.Stack(
    robot,
    [[hand, heading], [wb.PostureTask(robot, kp=2.0)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
    metric=np.r_[0.01, 0.01, np.ones(robot.nu - 2)],  # the two wheels first in u
)
q0 = robot.home()
start = robot.frame_pose(q0, hand.frame)
goal = start.copy()
goal[:3, 3] += (1.2, 0.0, 0.0)  # m, world: beyond the arm's reach from where the base stands
reference = wb.MinimumJerkTrajectory(start, goal, 4.0)
controller = wb.Controller(
    robot, stack, wb.ProjectionSolver(), dt=0.01, references={hand: reference}
)
log = controller.run(q0, 5.0)

q = np.asarray(log.meta["final_q"])
miss = np.linalg.norm(robot.frame_pose(q, hand.frame)[:3, 3] - goal[:3, 3])
drive = np.linalg.norm(robot.base_pose(q)[:2] - robot.base_pose(q0)[:2])
lo, hi = robot.position_limits
inside = np.all((log.joint_positions >= lo - 1e-9) & (log.joint_positions <= hi + 1e-9))
print(f"the hand ends {miss * 1e3:.3f} mm from its goal; the base drove {drive:.2f} m")
assert miss < 1e-3, f"the hand should end within 1 mm of its goal, it is {miss * 1e3:.2f} mm off"
assert drive > 0.5, f"the base should drive (the goal is out of the arm's reach): {drive:.2f} m"
assert inside, "a joint left its limits"

if args.viz:
    from wholebody.viz import replay

    replay(robot, log.t, log.q, draw=lambda scene: scene.marker("goal", goal[:3, 3]))
