"""A task of your own: the whole-body centre of mass moved 3 cm forward and 2 cm down.

The README's "Write your own task", the short way: the task gives its error `e(q)` and its
Jacobian `J = de/du` in actuated coordinates; the base class asks for `de/dt = -gain e`.
`wholebody.testing` checks the Jacobian against finite differences of the error before the
task is used with both solvers. (`wb.ComTask` is the built-in, compiled one.)

    python examples/custom_task.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb
from wholebody.testing import assert_task_jacobian

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the run in MeshCat")
args = parser.parse_args()


class CoMTask(wb.Task):
    """The centre of mass to a point: e = c - c_d (m, world), de/du = J_com (3 x nu)."""

    dim = 3

    def __init__(self, target: np.ndarray, gain: float = 5.0) -> None:
        super().__init__("com", 1.0, gain=gain)  # gain in 1/s
        self.target = np.asarray(target, dtype=float)

    def compute_error(self, state: wb.RobotState) -> np.ndarray:
        return state.com_position() - self.target

    def compute_jacobian(self, state: wb.RobotState) -> np.ndarray:
        return state.com_jacobian()


robot = wb.load_robot("mobile_humanoid")
q0 = robot.home()
com = CoMTask(robot.update(q0).com_position() + np.array([0.03, 0.0, -0.02]))
assert_task_jacobian(com, robot, q0, com.compute_error)  # J = de/du, or it raises
print("the CoM task's Jacobian matches finite differences")
for solver in (wb.ProjectionSolver(), wb.HierarchicalQPSolver()):
    stack = wb.Stack(
        robot,
        [[com], [wb.PostureTask(robot)]],
        [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
    )
    log = wb.Controller(robot, stack, solver, dt=0.01).run(q0, 3.0)  # 3 s at 100 Hz
    miss = np.linalg.norm(com.error(robot.update(log.meta["final_q"])))
    print(f"{solver.name}: the centre of mass ends {miss * 1e3:.4f} mm from its target")
    assert miss < 1e-4, f"{solver.name}: the CoM should end within 0.1 mm, {miss * 1e3:.3f} mm"

if args.viz:
    from wholebody.viz import replay

    replay(robot, log.t, log.q, draw=lambda scene: scene.marker("com_target", com.target))
