"""The Panda's hand moves 30 cm sideways past a box in its way, kept 1 cm off it.

`CollisionAvoidance` is a level above the hand: for every pair of the robot's links and the
box closer than 5 cm, a velocity-damper row keeps it at least 1 cm apart (the links drawn as
capsules, so the compiled kernel measures them). The straight way would take the hand closer;
the rows hold it at 1 cm as it passes. Needs the `robots` extra (example-robot-data's Panda
URDF): `pip install ".[robots]"`.

    python examples/panda_box.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("panda")
q0 = robot.home()
start = robot.frame_pose(q0, "panda_hand_tcp")
goal = start.copy()
goal[:3, 3] += (0.0, 0.3, 0.0)  # m, world: 30 cm to the left
box = np.eye(4)
box[:3, 3] = (start[:3, 3] + goal[:3, 3]) / 2 - (0.0, 0.0, 0.08)  # its top 3 cm under the way
obstacle = wb.Obstacle("box", "box", (0.1, 0.06, 0.1), box)
model = wb.CollisionModel(robot, [obstacle], self_collision=False, shapes={"*": "capsule"})
collision = wb.CollisionAvoidance(robot, model, safety=0.01, influence=0.05)
hand = wb.FrameTask(robot, "panda_hand_tcp", kp=10.0)  # its pose: it keeps pointing down
stack = wb.Stack(
    robot,
    [[collision], [hand], [wb.PostureTask(robot)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
reference = wb.MinimumJerkTrajectory(start, goal, 2.0)
controller = wb.Controller(
    robot, stack, wb.HierarchicalQPSolver(), dt=0.01, references={hand: reference}
)
log = controller.run(q0, 3.0)

closest = min(
    min((p.distance for p in model.distances(robot.update(q), 0.05)), default=0.05) for q in log.q
)
TOLERANCE = 5e-4  # m: the damper is first order in the step (the README measures 1 um)
miss = np.linalg.norm(log.frame_positions[hand.name][-1] - goal[:3, 3])
print(
    f"closest approach to the box {closest * 1e3:.2f} mm (safety {collision.safety * 1e3:.0f} mm)"
)
print(f"the hand ends {miss * 1e3:.2f} mm from its goal")
assert closest >= collision.safety - TOLERANCE, f"came {closest * 1e3:.2f} mm close to the box"
assert closest < collision.safety + 5e-3, "the box should be in the way (the rows should act)"
assert miss < 1e-3, f"the hand should reach its goal, it is {miss * 1e3:.2f} mm off"

if args.viz:
    from wholebody.viz import replay

    replay(robot, log.t, log.q, draw=lambda scene: scene.box("box", obstacle.size, box))
