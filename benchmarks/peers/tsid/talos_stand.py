#!/usr/bin/env python3
"""TSID on the TALOS standing problem: the peer side of issue 35's torque-level benchmark.

Run by the python of TSID's own virtual environment (``benchmarks/.venvs/tsid``, made by
``benchmarks/peers/tsid/setup.sh``), never by the dev venv: it imports tsid, pinocchio,
numpy and the standard library only (no wholebody). ``benchmarks/tsid_peer.py`` runs it as
a subprocess. It reads one JSON problem (stdin, or ``--problem FILE``) and prints one JSON
result on stdout; every field of the problem is optional (:data:`DEFAULTS`).

The problem. TALOS (example-robot-data's ``talos_full_v2.urdf``) on a free-flyer root,
the ``locked`` joints welded (``pinocchio.buildReducedModel``; a key may be an fnmatch
pattern such as ``gripper_*``), standing in the posture ``q0`` (joint name -> rad, the
others at 0; or ``"half_sitting"``, the SRDF's reference) with both soles flat at z = 0 (the
base height is shifted so that the soles' mean height is 0). TSID's
``InverseDynamicsFormulationAccForce`` over the variables ``x = (dv, f)``: ``dv`` the
generalised accelerations (nv; base twist in the base frame, 1/s^2 and m/s^2), ``f`` the
forces at the four corners of each sole (3 per corner, N, in the sole frame's axes: TSID's
local frame; the soles stand level, so up to their yaw these are world axes); torques are
eliminated (``tau = M dv + h - J_c^T f`` on the actuated rows). Levels:

* level 0 (hard): the base rows of ``M dv + h = J_c^T f`` (6), each sole's 6-D contact
  ``J_c dv + Jdot_c v = -Kp e - Kd J_c v`` (Kp = ``contact_kp``, Kd = 2 sqrt(Kp)), the
  friction pyramid of every corner force (``mu``; hence ``f_z >= 0`` at each corner: the
  centre of pressure stays inside the rectangle ``|x| <= lx``, ``|y| <= ly`` of the sole
  frame), ``fmin <= sum f_z <= fmax`` per sole, the URDF's torque limits (optional) and the
  joint position/velocity bounds as acceleration bounds (``TaskJointPosVelAccBounds``,
  optional; it looks 2 dt ahead, and with no acceleration limit set its viability bound
  takes 1e10 rad/s^2, i.e. none);
* level 1 (weighted sum of squares): the CoM task (``J_com dv + Jdot_com v = a_ref +
  Kd (v_ref - v_com) + Kp (p_ref - p_com)``, weight ``com_weight``, Kp ``com_kp`` 1/s^2,
  Kd = 2 sqrt(Kp)), the posture task on the actuated joints towards ``q0`` (``posture_weight``,
  ``posture_kp``), optionally both hands (``hands``: position-only SE(3) tasks towards
  targets ``hand_separation`` apart along world y), and TSID's force regularisation
  (``force_weight``; TSID's examples use 1e-5).

The CoM reference is ``com(t) = com0 + [0, A sin(2 pi f t), 0]`` (A = ``com_amplitude`` m,
f = ``com_frequency`` Hz) with its analytic velocity and acceleration. The loop runs
``steps`` steps of ``dt`` s: at time ``t_k = k dt``, ``formulation.computeProblemData`` and
``solver.solve`` (timed with ``time.perf_counter``), then a kinematic integration (no
simulator): ``v += dv dt``, ``q = pinocchio.integrate(q, v dt)``.

The result (JSON): ``versions``; ``solver``; ``nv``, ``na``; ``qp`` (``n_var``, ``n_eq``,
``n_in``: TSID's counts; the equalities and inequalities are level 0's rows, level 1 is only
the cost); ``solve_us`` (computeProblemData + solve), ``compute_us`` and ``qp_us`` (each
alone) and ``step_us`` (also the reference update, getAccelerations and the integration),
each as median, p10, p90 (us) without the first ``warmup`` steps; ``com_error_m``, the CoM
error ``|com(q_k) - com_ref(t_k)|`` (m) as rms and max over all steps (with the time of the
max), and ``com_error_second_half_m`` over the second half only (after the start's
transient: the reference starts at full speed, ``A w``, from rest); ``feet_drift`` (each
sole's final displacement from its start, m and rad); ``cop_margin_min_m`` and
``cop_margin_second_half_min_m``, the smallest distance of a sole's centre of pressure to
its rectangle's edge (m; 0: on the edge); ``torque_ratio_max`` (``max |tau_i| /
tau_max_i``); ``solver_failures`` (steps whose solver status is not 0);
``hand_error_final_m``; ``base_z0_m`` (the base height that puts the soles at z = 0). NaN
and infinite values (a diverged run) are written as null.
"""

from __future__ import annotations

import argparse
import fnmatch
import importlib.metadata
import json
import math
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import tsid

URDF = "robots/talos_data/robots/talos_full_v2.urdf"  # in example-robot-data's share
SRDF = "robots/talos_data/srdf/talos.srdf"

DEFAULTS: dict[str, Any] = {
    "locked": {"gripper_*": 0.0},  # joint name or fnmatch pattern -> position (rad)
    "q0": "half_sitting",  # or {joint name: rad} (the others at 0)
    "base": [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],  # xyz (m) + quaternion xyzw; z is re-set
    "feet": ["left_sole_link", "right_sole_link"],
    "lx": 0.1,  # sole half-length, forward/back (m)
    "ly": 0.065,  # sole half-width, left/right (m)
    "mu": 0.3,
    "fmin": 5.0,  # bounds of a sole's total normal force (N)
    "fmax": 1500.0,
    "contact_kp": 10.0,  # 1/s^2; Kd = 2 sqrt(Kp)
    "force_weight": 1e-5,  # TSID's force regularisation (its examples' value)
    "com_weight": 1.0,
    "com_kp": 100.0,
    "com_amplitude": 0.05,  # m, along world y
    "com_frequency": 0.5,  # Hz
    "posture_weight": 1e-3,
    "posture_kp": 10.0,
    "torque_limits": True,  # the URDF's effort limits, hard
    "joint_bounds": True,  # position and velocity limits as acceleration bounds, hard
    "hands": False,
    "hand_frames": ["gripper_left_base_link", "gripper_right_base_link"],
    "hand_separation": 0.3,  # m between the two hand targets, along world y
    "hand_weight": 1.0,
    "hand_kp": 100.0,
    "dt": 0.001,  # s
    "steps": 2000,
    "warmup": 10,  # first steps left out of the timing statistics
    "solver": "eiquadprog-fast",
}

SOLVERS = {"eiquadprog-fast": "SolverHQuadProgFast", "eiquadprog": "SolverHQuadProg"}


def fail(message: str) -> None:
    """Stop with ``message`` on stderr and exit status 2 (a bad problem or a missing file)."""
    print(f"talos_stand.py: {message}", file=sys.stderr)
    raise SystemExit(2)


def read_problem(argv: list[str] | None) -> dict[str, Any]:
    """The problem: :data:`DEFAULTS` updated with the JSON object read from ``--problem``
    or stdin (an empty input keeps the defaults). Unknown keys are an error."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problem", type=Path, help="JSON problem file (default: stdin)")
    args = parser.parse_args(argv)
    text = args.problem.read_text() if args.problem else sys.stdin.read()
    given = json.loads(text) if text.strip() else {}
    if not isinstance(given, dict):
        fail("the problem must be a JSON object")
    unknown = sorted(set(given) - set(DEFAULTS))
    if unknown:
        fail(f"unknown problem keys {unknown}; known: {sorted(DEFAULTS)}")
    for key, value in given.items():
        check_type(key, value)
    problem = {**DEFAULTS, **given}
    check_values(problem)
    return problem


def check_type(key: str, value: Any) -> None:
    """``value`` must have the type of ``DEFAULTS[key]`` (any number for a float, an int for
    an int; ``q0`` may also be ``"half_sitting"``)."""
    default = DEFAULTS[key]
    if key == "q0":
        ok = value == "half_sitting" or isinstance(value, dict)
    elif isinstance(default, bool | int):  # bool is an int: no float, no int for a bool
        ok = type(value) is type(default)
    elif isinstance(default, float):
        ok = isinstance(value, int | float) and not isinstance(value, bool)
    else:
        ok = isinstance(value, type(default))
    if not ok:
        expected = "a dict or 'half_sitting'" if key == "q0" else f"a {type(default).__name__}"
        fail(f"{key} = {value!r}: expected {expected} like {default!r}")


def check_values(problem: dict[str, Any]) -> None:
    """The values the loop and TSID need: positive sizes, gains and time step, a known
    solver, ``fmin <= fmax``, more steps than ``warmup``."""
    for key in ("lx", "ly", "mu", "fmin", "dt", "contact_kp", "com_kp", "posture_kp"):
        if not problem[key] > 0:
            fail(f"{key} = {problem[key]!r} must be positive")
    if problem["fmax"] < problem["fmin"]:
        fail(f"fmax = {problem['fmax']} is below fmin = {problem['fmin']}")
    if not 0 <= problem["warmup"] < problem["steps"]:
        fail(f"need 0 <= warmup ({problem['warmup']}) < steps ({problem['steps']})")
    if problem["solver"] not in SOLVERS:
        fail(f"solver {problem['solver']!r} is not one of {sorted(SOLVERS)} (TSID 1.10's)")
    if len(problem["feet"]) != 2 or len(problem["hand_frames"]) != 2:
        fail("feet and hand_frames must name two frames each")


def robot_data_share() -> Path:
    """example-robot-data's ``share/example-robot-data`` directory (its cmeel prefix), found
    through the installed distribution's file list."""
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        fail("example-robot-data is not installed in this venv (run setup.sh)")
    for f in files:
        parts = Path(str(f)).parts
        if "example-robot-data" in parts and parts[-1] == Path(URDF).name:
            i = parts.index("example-robot-data")
            return Path(str(f.locate())).parents[len(parts) - i - 2]
    fail(f"{Path(URDF).name} not found in the installed example-robot-data")
    raise AssertionError  # unreachable: fail() exits


def full_configuration(model: pin.Model, problem: dict[str, Any], share: Path) -> np.ndarray:
    """The configuration of the unreduced model: base pose, ``q0`` (or the SRDF's
    half-sitting) and the locked joints' values."""
    q = pin.neutral(model)
    if problem["q0"] == "half_sitting":
        pin.loadReferenceConfigurations(model, str(share / SRDF), False)
        q = model.referenceConfigurations["half_sitting"].copy()
    else:
        for name, value in problem["q0"].items():
            set_joint(model, q, name, float(value))
    base = np.asarray(problem["base"], dtype=float)
    if base.shape != (7,):
        fail("base must be [x, y, z, qx, qy, qz, qw]")
    q[:7] = base
    q[3:7] /= np.linalg.norm(base[3:])
    return q


def set_joint(model: pin.Model, q: np.ndarray, name: str, value: float) -> None:
    """Set the one-DOF joint ``name`` of ``q`` to ``value`` (rad or m)."""
    if not model.existJointName(name):
        fail(f"joint {name!r} is not in the URDF")
    joint = model.joints[model.getJointId(name)]
    if joint.nq != 1:
        fail(f"joint {name!r} has {joint.nq} coordinates; only 1-DOF joints can be set")
    q[joint.idx_q] = value


def locked_joints(model: pin.Model, locked: dict[str, float]) -> dict[str, float]:
    """``locked`` with its fnmatch patterns expanded to the model's joints (a later key wins).
    A key that matches no joint is an error."""
    names = list(model.names)[2:]  # below the universe and the free flyer
    out: dict[str, float] = {}
    for key, value in locked.items():
        matched = [n for n in names if fnmatch.fnmatchcase(n, key)]
        if not matched:
            fail(f"locked joint {key!r} matches no joint of the URDF")
        out.update(dict.fromkeys(matched, float(value)))
    return out


def build_model(problem: dict[str, Any]) -> tuple[pin.Model, np.ndarray, dict[str, float]]:
    """The reduced model (free flyer, locked joints welded), its start configuration with
    the soles at z = 0, and the locked joints."""
    share = robot_data_share()
    full = pin.buildModelFromUrdf(str(share / URDF), pin.JointModelFreeFlyer())
    q_full = full_configuration(full, problem, share)
    locked = locked_joints(full, problem["locked"])
    for name, value in locked.items():
        set_joint(full, q_full, name, value)
    ids = [full.getJointId(n) for n in locked]
    model = pin.buildReducedModel(full, ids, q_full)
    q = np.concatenate(
        [q_full[:7], [q_full[full.joints[full.getJointId(n)].idx_q] for n in list(model.names)[2:]]]
    )
    for frame in problem["feet"]:
        if not model.existFrame(frame):
            fail(f"foot frame {frame!r} is not in the model")
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    q[2] -= np.mean([data.oMf[model.getFrameId(f)].translation[2] for f in problem["feet"]])
    return model, q, locked


@dataclass
class Setup:
    """TSID's objects for one run: the robot, the formulation, its tasks and the solver."""

    robot: Any
    formulation: Any
    solver: Any
    com_task: Any
    com_sample: Any
    contacts: list[Any]
    others: list[Any] = field(default_factory=list)
    """The other tasks: the formulation holds them by reference, so Python must keep them."""
    hand_targets: dict[str, np.ndarray] = field(default_factory=dict)
    """The hand tasks' target positions (world, m), by frame."""


def sole_corners(lx: float, ly: float) -> np.ndarray:
    """The four corners of a sole in its frame (3 x 4, m), the sole frame at the sole."""
    return np.array([[-lx, -lx, lx, lx], [-ly, ly, -ly, ly], [0.0, 0.0, 0.0, 0.0]])


def add_contacts(robot: Any, formulation: Any, problem: dict[str, Any]) -> list[Any]:
    """One ``Contact6d`` per sole, held at its start placement (hard, level 0)."""
    contacts = []
    kp = problem["contact_kp"]
    data = formulation.data()
    for frame in problem["feet"]:
        contact = tsid.Contact6d(
            f"contact_{frame}",
            robot,
            frame,
            sole_corners(problem["lx"], problem["ly"]),
            np.array([0.0, 0.0, 1.0]),
            problem["mu"],
            problem["fmin"],
            problem["fmax"],
        )
        contact.setKp(kp * np.ones(6))
        contact.setKd(2.0 * math.sqrt(kp) * np.ones(6))
        contact.setReference(robot.framePosition(data, robot.model().getFrameId(frame)))
        formulation.addRigidContact(contact, problem["force_weight"])
        contacts.append(contact)
    return contacts


def add_bounds(robot: Any, formulation: Any, problem: dict[str, Any]) -> list[Any]:
    """The URDF's torque limits and joint position/velocity limits (hard, level 0)."""
    model = robot.model()
    na = robot.na
    tasks: list[Any] = []
    if problem["torque_limits"]:
        tau_max = np.asarray(model.effortLimit[-na:])
        task = tsid.TaskActuationBounds("torque-limits", robot)
        task.setBounds(-tau_max, tau_max)
        formulation.addActuationTask(task, 1.0, 0, 0.0)
        tasks.append(task)
    if problem["joint_bounds"]:
        task = tsid.TaskJointPosVelAccBounds("joint-bounds", robot, problem["dt"], False)
        task.setPositionBounds(model.lowerPositionLimit[7:], model.upperPositionLimit[7:])
        task.setVelocityBounds(np.asarray(model.velocityLimit[-na:]))
        formulation.addMotionTask(task, 1.0, 0, 0.0)
        tasks.append(task)
    return tasks


def add_posture(robot: Any, formulation: Any, problem: dict[str, Any], q0: np.ndarray) -> Any:
    """The posture task on the actuated joints towards ``q0`` (level 1)."""
    kp = problem["posture_kp"]
    task = tsid.TaskJointPosture("posture", robot)
    task.setKp(kp * np.ones(robot.na))
    task.setKd(2.0 * math.sqrt(kp) * np.ones(robot.na))
    sample = tsid.TrajectorySample(robot.na)
    sample.value(q0[7:])
    sample.derivative(np.zeros(robot.na))
    sample.second_derivative(np.zeros(robot.na))
    task.setReference(sample)
    formulation.addMotionTask(task, problem["posture_weight"], 1, 0.0)
    return task


def add_hands(
    robot: Any, formulation: Any, problem: dict[str, Any]
) -> tuple[list[Any], dict[str, np.ndarray]]:
    """Position-only SE(3) tasks moving the hands to targets ``hand_separation`` apart along
    world y, symmetric about their start midpoint, at their start x, z and orientation."""
    data = formulation.data()
    frames = problem["hand_frames"]
    for f in frames:
        if not robot.model().existFrame(f):
            fail(f"hand frame {f!r} is not in the model")
    start = [robot.framePosition(data, robot.model().getFrameId(f)) for f in frames]
    mid_y = 0.5 * (start[0].translation[1] + start[1].translation[1])
    tasks, targets = [], {}
    kp = problem["hand_kp"]
    for frame, placement, side in zip(frames, start, (1.0, -1.0), strict=True):
        task = tsid.TaskSE3Equality(f"hand_{frame}", robot, frame)
        task.setKp(kp * np.ones(6))
        task.setKd(2.0 * math.sqrt(kp) * np.ones(6))
        task.setMask(np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0]))
        target = placement.copy()
        target.translation[1] = mid_y + side * 0.5 * problem["hand_separation"]
        sample = tsid.TrajectorySE3Constant(f"target_{frame}", target).computeNext()
        task.setReference(sample)
        formulation.addMotionTask(task, problem["hand_weight"], 1, 0.0)
        tasks.append(task)
        targets[frame] = target.translation.copy()
    return tasks, targets


def build_setup(model: pin.Model, q0: np.ndarray, problem: dict[str, Any]) -> Setup:
    """The formulation with the contacts, bounds and tasks of the module docstring."""
    robot = tsid.RobotWrapper(model, tsid.FLOATING_BASE_SYSTEM, False)
    formulation = tsid.InverseDynamicsFormulationAccForce("tsid", robot, False)
    formulation.computeProblemData(0.0, q0, np.zeros(robot.nv))
    contacts = add_contacts(robot, formulation, problem)
    kp = problem["com_kp"]
    com_task = tsid.TaskComEquality("com", robot)
    com_task.setKp(kp * np.ones(3))
    com_task.setKd(2.0 * math.sqrt(kp) * np.ones(3))
    formulation.addMotionTask(com_task, problem["com_weight"], 1, 0.0)
    others = [add_posture(robot, formulation, problem, q0)]
    others += add_bounds(robot, formulation, problem)
    hand_targets: dict[str, np.ndarray] = {}
    if problem["hands"]:
        hand_tasks, hand_targets = add_hands(robot, formulation, problem)
        others += hand_tasks
    solver = getattr(tsid, SOLVERS[problem["solver"]])("solver")
    solver.resize(formulation.nVar, formulation.nEq, formulation.nIn)
    sample = tsid.TrajectorySample(3)
    return Setup(robot, formulation, solver, com_task, sample, contacts, others, hand_targets)


def com_reference(
    com0: np.ndarray, t: float, problem: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``com(t) = com0 + [0, A sin(w t), 0]`` and its first two derivatives (m, m/s,
    m/s^2), ``w = 2 pi f``."""
    a, w = problem["com_amplitude"], 2.0 * math.pi * problem["com_frequency"]
    s, c = math.sin(w * t), math.cos(w * t)
    axis = np.array([0.0, 1.0, 0.0])
    return com0 + a * s * axis, a * w * c * axis, -a * w * w * s * axis


def cop_margin(force: np.ndarray, lx: float, ly: float) -> float:
    """The distance of a sole's centre of pressure to the nearest edge of its rectangle
    (m; negative outside), from the four corner forces ``force`` (12, N): the CoP is the
    corners' mean weighted by their normal forces. The sole frame is taken as parallel to
    the ground (it starts so and the contact holds it)."""
    corners = sole_corners(lx, ly)
    fz = force[2::3]
    total = fz.sum()
    if total <= 0.0:
        return -math.inf
    cop = corners[:2] @ fz / total
    return float(min(lx - abs(cop[0]), ly - abs(cop[1])))


@dataclass
class Record:
    """What the loop measures, per step."""

    solve_s: list[float] = field(default_factory=list)
    compute_s: list[float] = field(default_factory=list)
    step_s: list[float] = field(default_factory=list)
    com_error: list[float] = field(default_factory=list)
    cop_margin: list[float] = field(default_factory=list)
    torque_ratio: list[float] = field(default_factory=list)
    failures: int = 0
    final_q: np.ndarray | None = None


def run(setup: Setup, q: np.ndarray, problem: dict[str, Any]) -> Record:
    """The control loop of the module docstring; returns the per-step measurements."""
    robot, formulation, solver = setup.robot, setup.formulation, setup.solver
    model, dt = robot.model(), problem["dt"]
    v = np.zeros(robot.nv)
    com0 = robot.com(formulation.data()).copy()
    tau_max = np.asarray(model.effortLimit[-robot.na :])
    rec = Record()
    for k in range(problem["steps"]):
        t = k * dt
        start = time.perf_counter()
        p, dp, ddp = com_reference(com0, t, problem)
        setup.com_sample.value(p)
        setup.com_sample.derivative(dp)
        setup.com_sample.second_derivative(ddp)
        setup.com_task.setReference(setup.com_sample)
        solve_start = time.perf_counter()
        hqp = formulation.computeProblemData(t, q, v)
        compute_end = time.perf_counter()
        sol = solver.solve(hqp)
        solve_end = time.perf_counter()
        dv = formulation.getAccelerations(sol)
        v += dv * dt
        q = pin.integrate(model, q, v * dt)
        rec.step_s.append(time.perf_counter() - start)
        rec.solve_s.append(solve_end - solve_start)
        rec.compute_s.append(compute_end - solve_start)
        rec.failures += sol.status != 0
        rec.com_error.append(float(np.linalg.norm(robot.com(formulation.data()) - p)))
        margins = [
            cop_margin(formulation.getContactForce(c.name, sol), problem["lx"], problem["ly"])
            for c in setup.contacts
        ]
        rec.cop_margin.append(min(margins))
        tau = formulation.getActuatorForces(sol)
        rec.torque_ratio.append(float(np.max(np.abs(tau) / tau_max)))
    rec.final_q = q
    return rec


def stats_us(seconds: list[float], warmup: int) -> dict[str, float]:
    """Median, p10 and p90 (us) of ``seconds`` without the first ``warmup`` samples."""
    x = np.asarray(seconds[warmup:]) * 1e6
    return {
        "median": float(np.median(x)),
        "p10": float(np.percentile(x, 10)),
        "p90": float(np.percentile(x, 90)),
        "n": len(x),
    }


def feet_drift(model: pin.Model, q0: np.ndarray, q1: np.ndarray, feet: list[str]) -> dict:
    """Each sole's displacement from ``q0`` to ``q1``: translation (m) and rotation angle
    (rad, of ``R0^T R1``)."""
    d0, d1 = model.createData(), model.createData()
    pin.framesForwardKinematics(model, d0, q0)
    pin.framesForwardKinematics(model, d1, q1)
    out = {}
    for f in feet:
        i = model.getFrameId(f)
        m0, m1 = d0.oMf[i], d1.oMf[i]
        out[f] = {
            "translation_m": float(np.linalg.norm(m1.translation - m0.translation)),
            "rotation_rad": float(np.linalg.norm(pin.log3(m0.rotation.T @ m1.rotation))),
        }
    return out


def hand_errors(model: pin.Model, q: np.ndarray, targets: dict[str, np.ndarray]) -> dict:
    """The distance of each hand frame to its target at ``q`` (m)."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return {
        f: float(np.linalg.norm(data.oMf[model.getFrameId(f)].translation - p))
        for f, p in targets.items()
    }


def versions() -> dict[str, str]:
    """The versions of what the run used."""
    out = {"python": platform.python_version()}
    for name in (
        "tsid",
        "libtsid",
        "pin",
        "eiquadprog",
        "cmeel-boost",
        "example-robot-data",
        "numpy",
    ):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def summarise(
    setup: Setup, rec: Record, q0: np.ndarray, locked: dict[str, float], problem: dict[str, Any]
) -> dict[str, Any]:
    """The JSON result (module docstring)."""
    model = setup.robot.model()
    assert rec.final_q is not None
    err = np.asarray(rec.com_error)
    dt = problem["dt"]
    half = len(err) // 2  # the second half: after the start's transient
    f = setup.formulation
    return {
        "peer": "tsid",
        "versions": versions(),
        "solver": problem["solver"],
        "nv": setup.robot.nv,
        "na": setup.robot.na,
        "locked": sorted(locked),
        "qp": {"n_var": f.nVar, "n_eq": f.nEq, "n_in": f.nIn},
        "steps": problem["steps"],
        "dt": problem["dt"],
        "solve_us": stats_us(rec.solve_s, problem["warmup"]),
        "compute_us": stats_us(rec.compute_s, problem["warmup"]),
        "qp_us": stats_us(list(np.subtract(rec.solve_s, rec.compute_s)), problem["warmup"]),
        "step_us": stats_us(rec.step_s, problem["warmup"]),
        "com_error_m": {
            "rms": float(np.sqrt(np.mean(err**2))),
            "max": float(err.max()),
            "max_at_s": float(np.argmax(err) * dt),
        },
        "feet_drift": feet_drift(model, q0, rec.final_q, problem["feet"]),
        "com_error_second_half_m": {
            "rms": float(np.sqrt(np.mean(err[half:] ** 2))),
            "max": float(err[half:].max()),
        },
        "cop_margin_min_m": float(min(rec.cop_margin)),
        "cop_margin_second_half_min_m": float(min(rec.cop_margin[half:])),
        "cop_margin_min_at_s": float(np.argmin(rec.cop_margin) * dt),
        "torque_ratio_max": float(max(rec.torque_ratio)),
        "solver_failures": rec.failures,
        "hand_error_final_m": hand_errors(model, rec.final_q, setup.hand_targets),
        "base_z0_m": float(q0[2]),
    }


def finite(value: Any) -> Any:
    """``value`` with its NaN and infinite floats replaced by None (strict JSON; a diverged
    run shows so)."""
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def main(argv: list[str] | None = None) -> None:
    """Read the problem, build TSID's formulation, run the loop, print the JSON result."""
    problem = read_problem(argv)
    model, q0, locked = build_model(problem)
    setup = build_setup(model, q0, problem)
    rec = run(setup, q0.copy(), problem)
    json.dump(finite(summarise(setup, rec, q0, locked, problem)), sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
