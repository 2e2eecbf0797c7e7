"""A reach under MuJoCo physics: the robot's inertia, its torque limits and joint servos.

The same controller drives a MuJoCo model built from the robot's own Pinocchio model
(`wholebody.sim.MujocoPlant`) and reads the simulated configuration back every 10 ms. The
hand follows a 2 s minimum-jerk reference to within a few millimetres. Needs the `sim`
extra (MuJoCo): `pip install ".[sim]"`.

    python examples/mujoco_physics.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb
from wholebody.sim import MujocoPlant

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the simulated run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("mobile_humanoid")
hand = wb.FrameTask(robot, "right_tool", kp=20.0, ki=5.0)
stack = wb.Stack(
    robot,
    [[hand], [wb.PostureTask(robot)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot), wb.AccelerationLimits(robot)],
)
q0 = robot.home()
start = robot.frame_pose(q0, hand.frame)
goal = start.copy()
goal[:3, 3] += (0.15, -0.1, 0.15)  # m, world
plant = MujocoPlant(robot)
plant.reset(q0)
reference = wb.MinimumJerkTrajectory(start, goal, 2.0)
controller = wb.Controller(
    robot, stack, wb.ProjectionSolver(), dt=0.01, references={hand: reference}, plant=plant
)
log = controller.run(q0, 3.0)

lag = np.linalg.norm(log.frame_positions[hand.name] - log.reference_positions[hand.name], axis=1)
print(
    f"under physics the hand stays within {lag.max() * 1e3:.2f} mm of its reference "
    f"({lag[-1] * 1e3:.3f} mm at the end); peak torques: {np.max(plant.log.torque_peak):.1f} N m"
)
assert log.meta.get("stopped") is None, f"the simulation stopped: {log.meta.get('stopped')}"
assert lag.max() < 5e-3, f"the hand should track within 5 mm, it lagged {lag.max() * 1e3:.2f} mm"

if args.viz:
    from wholebody.viz import replay

    replay(robot, log.t, log.q, draw=lambda scene: scene.marker("goal", goal[:3, 3]))
