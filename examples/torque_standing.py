"""TALOS standing on its soles under torque control: the centre of mass sways 3 cm sideways.

The torque-level backend (`wholebody.dynamics.DynamicsSolver`) turns a stack into joint
torques and the soles' wrenches, with the equations of motion, the friction pyramids and
the centres of pressure held; MuJoCo applies the torques at 1 kHz and is read back every
step. Needs the `robots` and `sim` extras: `pip install ".[robots,sim]"`.

    python examples/torque_standing.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb
from wholebody.dynamics import DynamicsSolver, PatchContact
from wholebody.dynamics.controller import TorqueController
from wholebody.sim import MujocoPlant

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the simulated run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("talos_full")
q0 = robot.home()
com = wb.ComTask(robot, "xyz", kp=5.0)  # 1/s: the CoM's velocity-level gain
upright = wb.FrameTask(robot, robot.base_frame, position=False, kp=5.0)
upright.set_target(robot.frame_pose(q0, robot.base_frame))
stack = wb.Stack(
    robot,
    [[com, upright], [wb.PostureTask(robot, kp=1.0)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
soles = ("left_sole_link", "right_sole_link")
feet = [  # TALOS's soles, 0.2 m x 0.13 m; the centre of pressure kept 2 cm inside
    PatchContact(f, mu=0.8, f_min=5.0, half_length=0.1, half_width=0.065, margin=0.02)
    for f in soles
]
solver = DynamicsSolver(robot, feet)
solver.make_contacts(q0)
plant = MujocoPlant(robot)
plant.reset(q0)
controller = TorqueController(robot, stack, solver, dt=0.001, plant=plant)
c0 = robot.com_position(q0)
q, u, errors, margins = q0, np.zeros(robot.nu), [], []
for k in range(2000):  # 2 s at 1 kHz: 3 cm to the left and back, from rest to rest
    t = k * 0.001
    target = c0 + np.array([0.0, 0.015 * (1.0 - np.cos(np.pi * t)), 0.0])
    com.set_target(target, [0.0, 0.015 * np.pi * np.sin(np.pi * t), 0.0])  # m, m/s
    result = controller.step(q, u)  # torques (N m) in result.tau, wrenches in result.wrenches
    q, u = controller.advance(q, u, result)  # MuJoCo's state after the step
    errors.append(np.linalg.norm(robot.com_position(q) - target))
    margins.append(min(c.cop_margin(result.wrenches[c.frame]) for c in feet))

slip = max(
    np.linalg.norm(robot.frame_pose(q, f)[:2, 3] - robot.frame_pose(q0, f)[:2, 3]) for f in soles
)
print(
    f"the CoM follows its sway within {max(errors) * 1e3:.2f} mm; the centres of pressure stay "
    f"{min(margins) * 1e3:.1f} mm or more inside the soles; the soles slide {slip * 1e3:.3f} mm"
)
assert plant.stop_reason is None, plant.stop_reason
assert max(errors) < 5e-3, f"the CoM should follow within 5 mm, it erred {max(errors) * 1e3:.2f} mm"
assert min(margins) > 0.019 and slip < 1e-3, (min(margins), slip)

if args.viz:
    from wholebody.viz import replay

    configurations = np.array(plant.log.configuration)
    replay(robot, np.arange(len(configurations)) * 0.001, configurations)
