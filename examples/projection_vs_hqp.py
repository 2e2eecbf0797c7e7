"""The projection and the hierarchical QP on one stack: the same answer where no bound acts.

Both backends take the same `Stack`. Where no limit is active both solve the same
lexicographic least-squares problem, so their `u` agree to round-off; both then reach the
same target in a closed loop.

    python examples/projection_vs_hqp.py [--viz]
"""

import argparse

import numpy as np

import wholebody as wb

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--viz", action="store_true", help="replay the HQP's run in MeshCat")
args = parser.parse_args()

robot = wb.load_robot("mobile_humanoid")
hands = [wb.FrameTask(robot, f, kp=5.0) for f in ("left_tool", "right_tool")]
stack = wb.Stack(
    robot,
    [hands, [wb.PostureTask(robot)]],
    [wb.JointPositionLimits(robot), wb.VelocityLimits(robot)],
)
q0 = robot.home()
for hand, shift in zip(hands, [(0.02, 0.01, 0.01), (0.01, -0.02, 0.02)], strict=True):
    goal = robot.frame_pose(q0, hand.frame)
    goal[:3, 3] += shift  # m, world
    hand.set_target(goal)

solvers = (wb.ProjectionSolver(), wb.HierarchicalQPSolver())
results = [s.solve(stack, robot.update(q0), dt=0.01) for s in solvers]
gap = np.abs(results[0].u - results[1].u).max()
print(
    f"one step from home: the two u differ by {gap:.1e} (rad/s, m/s); "
    f"statuses {[r.status.name for r in results]}"
)
assert all(r.status == wb.SolverStatus.OK for r in results), "no bound should be active"
assert gap < 1e-9, f"without active bounds the backends should agree, they differ by {gap:.1e}"

for solver in solvers:
    log = wb.Controller(robot, stack, solver, dt=0.01).run(q0, 3.0)
    q = np.asarray(log.meta["final_q"])
    miss = max(np.linalg.norm(robot.frame_pose(q, h.frame)[:3, 3] - h.target[:3, 3]) for h in hands)
    print(f"{solver.name}: both hands within {miss * 1e3:.4f} mm of their targets after 3 s")
    assert miss < 1e-4, f"{solver.name} should reach both targets, {miss * 1e3:.3f} mm off"

if args.viz:
    from wholebody.viz import replay

    replay(robot, log.t, log.q)
