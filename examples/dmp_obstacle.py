"""A movement learned from one demonstration, replayed to a new goal around a cylinder.

`DMP.fit` learns the demonstration's shape; `rollout` generalises it to a new goal with the
paper's dynamic potential pushing the path off a cylinder standing in its way. Without the
potential the same rollout passes through the cylinder; with it the path keeps off it and
still ends at the goal.

    python examples/dmp_obstacle.py [--viz]
"""

import argparse

import numpy as np

from wholebody.planning import DMP, DynamicPotential, cylinder, cylinder_distance

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="show the paths in MeshCat")
args = parser.parse_args()

t = np.linspace(0.0, 1.0, 200)  # s
demo = np.stack([0.3 * t, 0.1 * np.sin(np.pi * t), 0.2 * t**2], axis=1)  # m
dmp = DMP.fit(demo, t)
goal = np.array([0.35, 0.0, 0.25])  # m: a goal the demonstration never reached
centre, radius, height = np.array([0.15, 0.05, 0.07]), 0.04, 0.2  # m, axis vertical
free = dmp.rollout(160, goal=goal).positions
path = dmp.rollout(160, goal=goal, obstacles=[DynamicPotential(cylinder(centre, radius, height))])
path = path.positions

inside = cylinder_distance(free, centre, radius, height).min()
clearance = cylinder_distance(path, centre, radius, height).min()
miss = np.linalg.norm(path[-1] - goal)
print(
    f"without the potential the path enters the cylinder (distance {inside * 1e3:.1f} mm); "
    f"with it the path keeps {clearance * 1e3:.1f} mm off it and ends {miss * 1e3:.3f} mm "
    "from the goal"
)
assert inside == 0.0, "the cylinder should stand in the free path's way"
assert clearance > 0.0, f"the path should keep off the cylinder, it came {clearance:.4f} m close"
assert miss < 1e-3, f"the path should end at the goal, it ends {miss * 1e3:.2f} mm off"

if args.viz:
    import wholebody as wb
    from wholebody.viz import replay

    SHIFT = np.array([0.5, 0.0, 0.6])  # m: shown in front of the robot
    pose = np.eye(4)
    pose[:3, 3] = centre + SHIFT  # shown in front of the robot
    robot = wb.load_robot("mobile_humanoid")

    def draw(scene):  # the paths and the cylinder beside the robot at home
        scene.path("free", free + SHIFT, color="#999999")
        scene.path("dmp", path + SHIFT)
        scene.cylinder("cylinder", radius, height, pose)

    replay(robot, np.zeros(1), robot.home()[None], draw=draw)
