#!/usr/bin/env python3
"""Write the notebooks of this folder, executed (run it after editing the cells below).

``python notebooks/make_notebooks.py`` writes each notebook's cells and runs it top to
bottom in a Jupyter kernel (``nbclient``, the ``dev`` extra), so that the notebooks ship
with their outputs, figures included, and open ready to read; ``--no-execute`` writes the
cells only. Open them with ``jupyter lab notebooks/`` (``pip install ".[dev]"``).

``tests/test_notebooks.py`` checks that the shipped notebooks are these cells, that every
code cell has its outputs, and (slow) that executing them again gives the same outputs
(numbers, paths and figures' pixels aside).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

QUICKSTART = [
    new_markdown_cell(
        "# wholebody quickstart\n\n"
        "Load the paper's 23-DOF mobile humanoid, compose a task stack in Python, run a "
        "closed-loop reach and plot it. Units are SI (m, rad, s); the world's z is up."
    ),
    new_code_cell(
        "import matplotlib.pyplot as plt\n"
        "import numpy as np\n"
        "import pinocchio as pin\n\n"
        "import wholebody\n\n"
        "robot = wholebody.load_robot('mobile_humanoid')\n"
        "print(robot.summary())"
    ),
    new_markdown_cell(
        "## Frames, poses and Jacobians\n\n"
        "`u` is the **actuated velocity**: the 4 wheel speeds first (through the Mecanum "
        "matrix), then the 19 joint speeds. A Jacobian has one column per entry of `u`."
    ),
    new_code_cell(
        "q = robot.neutral()                      # the paper's initial state, arms hanging\n"
        "hand = robot.frame('right_tool')\n"
        "print(np.round(robot.frame_pose(q, hand), 4))\n"
        "J = robot.frame_jacobian(q, hand)\n"
        "print('Jacobian', J.shape, '; wheel columns:', np.round(J[:3, :4], 4).tolist())"
    ),
    new_markdown_cell(
        "## A stack\n\n"
        "Level 1: the right hand tracks a pose with the paper's PI law. Level 2: the paper's "
        "objective `H` (arm energy, joint-limit avoidance), descended in the null space. "
        "Joint position and velocity limits hold at every level."
    ),
    new_code_cell(
        "from wholebody.presets import paper_metric\n"
        "from wholebody.solvers import Level, ProjectionSolver, Stack\n"
        "from wholebody.tasks import (\n"
        "    ArmPotentialEnergy,\n"
        "    FrameTask,\n"
        "    JointLimitAvoidance,\n"
        "    JointPositionLimits,\n"
        "    VelocityLimits,\n"
        ")\n\n"
        "right = FrameTask(robot, 'right_tool', kp=20.0, ki=5.0)\n"
        "objectives = [\n"
        "    ArmPotentialEnergy(robot, 'left', stiffness=0.1, weight=0.5),\n"
        "    ArmPotentialEnergy(robot, 'right', stiffness=0.1, weight=0.5),\n"
        "    JointLimitAvoidance(robot, ['left_arm', 'right_arm'], weight=0.05, name='h1_arms'),\n"
        "    JointLimitAvoidance(robot, ['waist'], weight=30.0, name='h1_waist'),\n"
        "]\n"
        "stack = Stack(robot, [[right], Level(objectives, gain=1.0)],\n"
        "              [JointPositionLimits(robot), VelocityLimits(robot)],\n"
        "              metric=paper_metric(robot))\n"
        "stack"
    ),
    new_markdown_cell("## A reach to the paper's object B, closed loop at 100 Hz"),
    new_code_cell(
        "from wholebody.control import Controller, summary\n"
        "from wholebody.planning.trajectory import MinimumJerkTrajectory\n\n"
        "start = robot.frame_pose(q, hand)\n"
        "goal = start.copy()\n"
        "goal[:3, 3] = [1.701, -0.45675, 0.46133]\n"
        "point_forward = pin.exp3(np.array([0.0, -np.pi / 2, 0.0]))\n"
        "goal[:3, :3] = point_forward @ start[:3, :3]\n"
        "monitors = [ArmPotentialEnergy(robot, a, 0.1) for a in ('left', 'right')]\n"
        "controller = Controller(robot, stack, ProjectionSolver(), dt=0.01,\n"
        "                        references={right: MinimumJerkTrajectory(start, goal, 5.0)},\n"
        "                        monitors=monitors)\n"
        "log = controller.run(q, 5.0)\n"
        "m = summary(log)\n"
        "print('MAE (mm):', {k: round(v * 1e3, 3) for k, v in m['mae_m']['right_tool'].items()})\n"
        "print('waist travel (rad):', round(m['joint_travel_rad']['waist'], 3))\n"
        "print('median control step (us):', round(m['step_time_us']['median']))"
    ),
    new_code_cell(
        "fig, axes = plt.subplots(1, 2, figsize=(11, 3.5))\n"
        "p, r = log.frame_positions['right_tool'], log.reference_positions['right_tool']\n"
        "for i, axis in enumerate('xyz'):\n"
        "    axes[0].plot(log.t, p[:, i], label=f'{axis}')\n"
        "    axes[0].plot(log.t, r[:, i], 'k--', lw=0.8)\n"
        "axes[0].set(xlabel='time (s)', ylabel='right hand (m)')\n"
        "axes[0].legend()\n"
        "axes[1].plot(log.t, log.arms['right'].gravity, label='gravity')\n"
        "axes[1].plot(log.t, log.arms['right'].spring, label='spring')\n"
        "axes[1].set(xlabel='time (s)', ylabel='right arm energy (J)')\n"
        "axes[1].legend()\n"
        "fig.tight_layout()"
    ),
    new_markdown_cell(
        "Scenario files run the paper's experiments from the command line: "
        "`wholebody run coordinated_carry --viz` (live in MeshCat, localhost only), "
        "`wholebody compare coordinated_carry` (its Table 2)."
    ),
]

COMPARE = [
    new_markdown_cell(
        "# Projection or hierarchical QP?\n\n"
        "The same stack and the same reach, solved by the plain pseudo-inverse (the paper's "
        "baseline), the paper's energy-shaped projection, and the hierarchical QP. The "
        "projection handles the joint box by Saturation in the Null Space; the QP keeps it as "
        "a hard constraint at every level."
    ),
    new_code_cell(
        "import matplotlib.pyplot as plt\n"
        "import numpy as np\n"
        "import pinocchio as pin\n\n"
        "import wholebody\n"
        "from wholebody.control import Controller, summary\n"
        "from wholebody.planning.trajectory import MinimumJerkTrajectory\n"
        "from wholebody.presets import paper_stack\n"
        "from wholebody.scenarios import make_solver\n"
        "from wholebody.tasks import ArmPotentialEnergy, FrameTask\n\n"
        "robot = wholebody.load_robot('mobile_humanoid')\n"
        "q0 = robot.neutral()\n\n"
        "def reach(backend):\n"
        "    hand = FrameTask(robot, 'right_tool', kp=20.0, ki=5.0)\n"
        "    start = robot.frame_pose(q0, hand.frame)\n"
        "    goal = start.copy()\n"
        "    goal[:3, 3] = [1.701, -0.45675, 0.46133]\n"
        "    goal[:3, :3] = pin.exp3(np.array([0, -np.pi / 2, 0])) @ start[:3, :3]\n"
        "    stack = paper_stack(robot, [hand], objectives=backend != 'pinv', stiffness=0.1)\n"
        "    monitors = [ArmPotentialEnergy(robot, a, 0.1) for a in ('left', 'right')]\n"
        "    ref = {hand: MinimumJerkTrajectory(start, goal, 5.0)}\n"
        "    return Controller(robot, stack, make_solver(backend), dt=0.01, references=ref,\n"
        "                      monitors=monitors).run(q0, 5.0)\n\n"
        "logs = {b: reach(b) for b in ('pinv', 'projection', 'hqp')}\n"
        "print({b: f'{len(log)} steps' for b, log in logs.items()})"
    ),
    new_code_cell(
        "rows = []\n"
        "for b, log in logs.items():\n"
        "    m = summary(log)\n"
        "    rows.append((b, m['step_time_us']['median'],\n"
        "                 max(m['mae_m']['right_tool'].values()) * 1e3,\n"
        "                 m['joint_travel_rad']['waist'], m['arm_energy_j']['right']['final'],\n"
        "                 m['limit_violations'], m['solver_failures']))\n"
        "print(f\"{'backend':12s} {'step us':>8s} {'max MAE mm':>10s} {'waist rad':>9s} \"\n"
        "      f\"{'E right J':>9s} {'viol':>5s} {'fail':>5s}\")\n"
        "for r in rows:\n"
        "    b, t, mae, waist, energy, viol, fail = r\n"
        "    print(f'{b:12s} {t:8.0f} {mae:10.4f} {waist:9.3f} {energy:9.3f} {viol:5d} {fail:5d}')"
    ),
    new_code_cell(
        "fig, axes = plt.subplots(1, 3, figsize=(13, 3.3), sharey=True)\n"
        "names = robot.group('waist').joints\n"
        "for ax, (b, log) in zip(axes, logs.items(), strict=True):\n"
        "    for j, name in zip(robot.group('waist').indices, names, strict=True):\n"
        "        ax.plot(log.t, log.joint_positions[:, j], label=name)\n"
        "    ax.set(title=b, xlabel='time (s)')\n"
        "axes[0].set_ylabel('waist joint (rad)')\n"
        "axes[0].legend(fontsize=7)\n"
        "fig.tight_layout()"
    ),
    new_markdown_cell(
        "Less waist and a lower final arm energy with the objectives: the paper's \"more arm, "
        'less waist". The QP reaches the same motion with its bounds as hard constraints.'
    ),
]


NOTEBOOKS = {"quickstart.ipynb": QUICKSTART, "compare_solvers.ipynb": COMPARE}


def notebook(cells: list) -> nbformat.NotebookNode:
    """A notebook of ``cells`` for the ``python3`` kernel (no outputs yet)."""
    nb = new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    return nb


def execute(nb: nbformat.NotebookNode, cwd: Path = HERE, timeout: int = 600) -> None:
    """Run every cell of ``nb`` in a fresh ``python3`` kernel started in ``cwd``, in place
    (outputs and execution counts filled in; ``timeout`` s a cell). Figures are captured by
    the kernel's inline backend (as PNGs), so ``MPLBACKEND`` must not name another one. The
    cells' timing metadata is dropped: it changes at every run and says nothing."""
    import nbclient

    nbclient.NotebookClient(
        nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(cwd)}}
    ).execute()
    for cell in nb.cells:
        cell.metadata.pop("execution", None)


def write(name: str, cells: list, run: bool = True) -> Path:
    """Write ``notebooks/<name>`` from ``cells``, executed unless ``run`` is False."""
    nb = notebook(cells)
    if run:
        execute(nb)
    path = HERE / name
    nbformat.write(nb, path)
    print(f"wrote {path}" + (" (executed)" if run else ""))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-execute", action="store_true", help="write the cells only")
    args = parser.parse_args()
    for name, cells in NOTEBOOKS.items():
        write(name, cells, run=not args.no_execute)


if __name__ == "__main__":
    main()
