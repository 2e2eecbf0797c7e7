"""The UR5's elbow sent to 3.5 rad, past its limit of pi: it stops at the limit, never beyond.

A posture task on the elbow alone sits above a posture task on every joint. The position
limit holds the elbow at pi; the result says the elbow task is unmet and why: at a joint
position limit (`wholebody.solvers.unmet`, the same analysis the run logs record). Needs the
`robots` extra (example-robot-data's UR5 URDF): `pip install ".[robots]"`.

    python examples/ur5_joint_limit.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb
from wholebody.solvers.unmet import UnmetCause

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("ur5")
elbow = robot.actuated_joints.index("elbow_joint")
lower, upper = robot.position_limits
reach = wb.PostureTask(robot, ["elbow_joint"], name="elbow", target=[3.5], kp=2.0)  # rad
stack = wb.Stack(
    robot,
    [[reach], [wb.PostureTask(robot)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
controller = wb.Controller(robot, stack, wb.HierarchicalQPSolver(), dt=0.01)
q = robot.home()
qs = [q]
for _ in range(300):  # 3 s at 100 Hz
    controller.step(q)
    q = controller.q_next.copy()
    qs.append(q)
    angles = robot.joint_positions(q)
    assert np.all((angles >= lower - 1e-9) & (angles <= upper + 1e-9)), "a joint left its limits"

result = controller.result
print(result.report())
cause = result.causes()["elbow"]  # why the elbow task is unmet (an UnmetCause)
print(
    f"elbow at {robot.joint_positions(q)[elbow]:.6f} rad (limit {upper[elbow]:.6f}); "
    f"the elbow task is unmet: {cause.name}"
)
assert abs(robot.joint_positions(q)[elbow] - upper[elbow]) < 1e-6, "the elbow should rest at pi"
assert cause == UnmetCause.JOINT_LIMIT, f"the cause should be the joint limit, got {cause.name}"
assert "elbow_joint" in result.report(), "the report should name the joint at its limit"

if args.viz:
    from wholebody.viz import replay

    replay(robot, np.arange(len(qs)) * 0.01, np.array(qs))
