"""A reachability map: 225 reaches of a fixed-base torso's right hand, in batched solves.

`Controller.step_many` runs many independent states of one stack in one kernel call per
core: here every state starts at home and reaches for its own target of a 15 x 15 grid in a
vertical plane through the hand, 3 s at 100 Hz each. A target counts as reachable when the
hand ends within 1 mm of it: kinematically, collisions unchecked, and a target that a local
minimum keeps the reach from counts as unreachable. Near targets are, far ones are not.

    python examples/reachability_map.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="show the map's targets in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("dual_arm_torso")
hand = wb.FrameTask(robot, "right_tool", kp=10.0, orientation=False)
stack = wb.Stack(
    robot,
    [[hand], [wb.PostureTask(robot)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
controller = wb.Controller(robot, stack, wb.HierarchicalQPSolver(), dt=0.01)
q0 = robot.home()
home = robot.frame_pose(q0, hand.frame)
x, z = np.meshgrid(np.linspace(-0.2, 1.0, 15), np.linspace(-0.6, 0.6, 15))  # m from the hand
targets = np.repeat(home[None], x.size, axis=0)
targets[:, 0, 3] += x.ravel()
targets[:, 2, 3] += z.ravel()
batch = controller.step_many(np.repeat(q0[None], x.size, axis=0), {hand: targets}, steps=300)
miss = np.linalg.norm(batch.errors[hand.name][:, :3], axis=1)  # m, at the last step
reachable = miss < 1e-3
print(f"{reachable.mean():.0%} of {x.size} targets reachable (hand within 1 mm after 3 s)")
for row in reachable.reshape(x.shape)[::-1]:  # top row first: '#' reachable
    print("".join("#" if r else "." for r in row))
assert reachable.any() and not reachable.all(), "the grid should hold reachable and unreachable"
assert reachable.reshape(x.shape)[7, 2], "a target near the hand's home should be reachable"

if args.viz:
    from wholebody.viz import replay

    def draw(scene):
        for k, (p, r) in enumerate(zip(targets[:, :3, 3], reachable, strict=True)):
            scene.marker(f"t{k}", p, color="#2ca02c" if r else "#d62728", radius=0.01)

    replay(robot, np.zeros(1), q0[None], draw=draw)
