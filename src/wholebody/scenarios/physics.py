"""The metrics a physics run adds to a scenario's (:func:`physics_metrics`).

Torques are the plant's applied ones (:class:`wholebody.sim.PhysicsLog`): the peak per joint
group (N m; a wheeled base's wheels carry the torque that drives the planar base, ``B^T W``),
the base's peak force (N) and yaw torque (N m), and the joints that reached their limit.
A grasp's force is the weld's force on the object (N, world). While two hands hold one
object, its **squeeze** is the internal force along the line between the hands::

    s = (F_a . n - F_b . n) / 2,        n = (p_b - p_a) / |p_b - p_a|

with ``F_a``, ``F_b`` the hands' forces on the object and ``p_a``, ``p_b`` their tool frames:
positive when the hands press the object together, negative when they pull it apart; the
object's weight and acceleration, which both hands share, cancel from it.

A run through a sensor (:class:`~wholebody.control.JointSensor`: noise, a delay) logs what
the controller saw; :func:`true_tracking` measures the hands and the closed chain on the
simulated configuration instead (``PhysicsLog.configuration``), the robot's true state.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from wholebody.control import RunLog
from wholebody.robot import Frame, Robot
from wholebody.scenarios.spec import ObjectSpec

__all__ = ["physics_metrics", "physics_poses", "physics_records", "true_tracking"]


def physics_poses(objects: Mapping[str, ObjectSpec], physics: dict) -> dict[str, np.ndarray]:
    """(N, 4, 4) pose of every object: the simulated one of a free object, else its own."""
    n = len(physics["torque_peak"])
    out = {}
    for name, obj in objects.items():
        if name in physics["object_poses"]:
            out[name] = physics["object_poses"][name]
            continue
        out[name] = np.repeat(obj.pose[None], n, axis=0)
    return out


def physics_records(plant, log: RunLog, frames: Mapping[str, Frame]) -> dict:
    """The plant's records (:meth:`wholebody.sim.PhysicsLog.arrays`) with, per step,
    ``group_torque`` (group -> (N, joints) peak |torque| (N m) and ``group_limit`` its
    joints' limits; a wheeled base's wheels carry ``B^T W``), ``squeeze`` (object -> (N,)
    N, NaN unless two hands hold it) and ``hands`` (hand frame -> hand name)."""
    rec = plant.log.arrays()
    robot = plant.robot
    names = [plant.dof_name(k) for k in range(robot.nv)]
    torque = dict(zip(names, rec["torque_peak"].T, strict=True))
    limit = dict(zip(names, plant.world.effort, strict=True))
    if rec["wheel_torque_peak"].size:
        torque.update(zip(robot.base.wheel_joints, rec["wheel_torque_peak"].T, strict=True))
    rec["group_torque"], rec["group_limit"] = {}, {}
    for g in robot.groups.values():
        joints = [j for j in g.joints if j in torque]
        if joints:
            rec["group_torque"][g.name] = np.stack([torque[j] for j in joints], axis=1)
            rec["group_limit"][g.name] = np.array([limit[j] for j in joints])
    rec["hands"] = {f.name: h for h, f in frames.items()}
    rec["squeeze"] = _squeeze(rec["grasp_force"], log, rec["hands"])
    return rec


def physics_metrics(plant, rec: dict) -> dict:
    """``torque_peak_nm`` and ``torque_peak_fraction`` (of the limit) per group,
    ``base_force_peak_n`` (the largest world x or y force on a planar base, N) and
    ``base_torque_peak_nm`` (its yaw torque), ``torque_saturated`` (joint -> share
    of steps at the limit), ``grasp_force_peak_n`` (object -> hand -> N),
    ``squeeze_force_n`` (object -> peak |s| and mean s, N) and ``contacts`` (each robot shape
    that touched an object: when first and how hard)."""
    peak = {g: t.max(axis=0, initial=0.0) for g, t in rec["group_torque"].items()}
    saturated = rec["saturated"].mean(axis=0) if len(rec["saturated"]) else []
    m: dict = {
        "torque_peak_nm": {g: float(p.max()) for g, p in peak.items()},
        "torque_peak_fraction": {
            g: float((p / rec["group_limit"][g]).max()) for g, p in peak.items()
        },
        "torque_saturated": {
            plant.dof_name(k): float(share) for k, share in enumerate(saturated) if share > 0
        },
    }
    if plant.planar and len(rec["torque_peak"]):
        m["base_force_peak_n"] = float(rec["torque_peak"][:, :2].max())
        m["base_torque_peak_nm"] = float(rec["torque_peak"][:, 2].max())
    grasp: dict[str, dict[str, float]] = {}
    for (obj, frame), force in rec["grasp_force"].items():
        norm = np.linalg.norm(force, axis=1)
        grasp.setdefault(obj, {})[rec["hands"][frame]] = float(norm.max()) if len(norm) else 0.0
    m["grasp_force_peak_n"] = grasp
    m["squeeze_force_n"] = {
        obj: {"peak": float(np.nanmax(np.abs(s))), "mean": float(np.nanmean(s))}
        for obj, s in rec["squeeze"].items()
    }
    first = sorted(rec["contacts"].items(), key=lambda item: item[1][0])
    m["contacts"] = [{"pair": k, "first_s": t, "peak_force_n": f} for k, (t, f) in first]
    return m


def _squeeze(
    forces: Mapping[tuple[str, str], np.ndarray], log: RunLog, hands: Mapping[str, str]
) -> dict[str, np.ndarray]:
    """Per object held by two hands at some step: the squeeze (N) at every step, NaN where
    fewer than two hold it."""
    out: dict[str, np.ndarray] = {}
    for obj in sorted({o for o, _ in forces}):
        held = [(hands[f], F) for (o, f), F in forces.items() if o == obj]
        if len(held) != 2:
            continue
        (a, Fa), (b, Fb) = held
        both = (np.abs(Fa).sum(axis=1) > 0) & (np.abs(Fb).sum(axis=1) > 0)
        if not both.any():
            continue
        gap = log.frame_positions[b][: len(Fa)] - log.frame_positions[a][: len(Fa)]
        n = gap / np.maximum(np.linalg.norm(gap, axis=1, keepdims=True), 1e-12)
        s = 0.5 * (np.einsum("ij,ij->i", Fa, n) - np.einsum("ij,ij->i", Fb, n))
        out[obj] = np.where(both, s, np.nan)
    return out


def true_tracking(
    robot: Robot,
    log: RunLog,
    configuration: np.ndarray,
    hands: Mapping[str, Frame],
    chains: list[tuple[np.ndarray, Frame, Frame]],
) -> dict:
    """The hands' tracking and the closed chain on the simulated configuration
    ``configuration`` ((N, nq), one row per logged step), not on the one the controller saw.

    ``hands``: hand -> its frame (the log's tracked tasks); ``chains``: per closed-chain phase
    its steps' mask and the chain's primary and secondary frames. Returned (m):
    ``true_max_tracking_error_m`` and ``true_mean_tracking_error_m`` (hand -> over the steps
    with a reference) and ``true_closed_chain_error_max_m``: the largest distance of the
    secondary's true position in the primary's frame from the chain's target, the target
    being what the controller saw plus its logged error (``e = target - p`` in the primary's
    axes, :mod:`wholebody.kernels.rows`).
    """
    q = configuration[: len(log)]
    out: dict = {"true_max_tracking_error_m": {}, "true_mean_tracking_error_m": {}}
    for hand, frame in hands.items():
        ref = log.reference_positions[hand]
        rows = np.flatnonzero(np.isfinite(ref).all(axis=1))
        p = np.array([robot.frame_pose(q[k], frame)[:3, 3] for k in rows]).reshape(-1, 3)
        e = np.linalg.norm(p - ref[rows], axis=1)
        out["true_max_tracking_error_m"][hand] = float(e.max(initial=0.0))
        out["true_mean_tracking_error_m"][hand] = float(e.mean()) if e.size else 0.0
    chain = 0.0
    for mask, a, b in chains:
        for k in np.flatnonzero(mask):
            target = _relative(robot, log.q[k], a, b) + log.task_errors["closed_chain"][k, :3]
            chain = max(chain, float(np.linalg.norm(target - _relative(robot, q[k], a, b))))
    out["true_closed_chain_error_max_m"] = chain
    return out


def _relative(robot: Robot, q: np.ndarray, a: Frame, b: Frame) -> np.ndarray:
    """Frame b's position in frame a (m, a's axes): ``R_a^T (p_b - p_a)``."""
    Ta, Tb = robot.frame_pose(q, a), robot.frame_pose(q, b)
    return Ta[:3, :3].T @ (Tb[:3, 3] - Ta[:3, 3])
