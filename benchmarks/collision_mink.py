#!/usr/bin/env python3
"""Collision constraint cost: wholebody's :class:`CollisionAvoidance` against mink's
``CollisionAvoidanceLimit``, on the same shapes and pairs of the paper's robot.

The URDF's own primitives (boxes, cylinders, spheres; the hands kept as in the URDF) are
loaded by Pinocchio/coal for wholebody and by MuJoCo (``fusestatic="false"``, so every link
keeps its body) for mink; mink gets exactly wholebody's pairs, shape to geom by link and
order. The base is fixed at the origin (MuJoCo welds the URDF's root to the world). At
``--n`` random postures (seed 0), interleaved, one thread: the time of (a) wholebody
``task.compute(robot.update(q), 0.01)`` (the Python task: rows, bounds, names), (b) wholebody
``robot.update(q)`` + the kernel :func:`~wholebody.kernels.collision.collision_rows` (what the
control step calls: 32 rows at most) and (c) mink ``configuration.update(qpos)`` +
``limit.compute_qp_inequalities(configuration, 0.01)``; the pairs each finds within the
detection distance (5 cm), and the largest distance difference of the pairs both find.

    python benchmarks/collision_mink.py [--n N]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import mujoco
import numpy as np
from mink import CollisionAvoidanceLimit, Configuration
from threadpoolctl import threadpool_limits

import wholebody as wb
from wholebody.collision import CollisionModel
from wholebody.kernels.collision import RESULT_WIDTH, collision_rows

SAFETY, DETECTION, DT = 0.01, 0.05, 0.01
MJ_TYPE = {
    "Box": mujoco.mjtGeom.mjGEOM_BOX,
    "Cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "Sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
}


def load_mujoco(urdf: Path) -> mujoco.MjModel:
    """The URDF in MuJoCo, each link its own body (no fusing of fixed joints)."""
    text = urdf.read_text()
    head = text.index(">", text.index("<robot")) + 1
    extra = '<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco>'
    try:
        return mujoco.MjModel.from_xml_string(text[:head] + extra + text[head:])
    except ValueError as err:
        raise SystemExit(f"MuJoCo cannot load {urdf}: {err}") from err


def geom_map(model: CollisionModel, mj: mujoco.MjModel) -> list[int]:
    """MuJoCo geom of each wholebody shape: the k-th geom of the link's body, same type."""
    out, seen = [], {}
    for i, obj in enumerate(model.geometry.geometryObjects[: model.n_robot]):
        link = model.link(i)
        k = seen[link] = seen.get(link, -1) + 1
        body = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_BODY, link)
        geoms = np.flatnonzero(mj.geom_bodyid == body) if body >= 0 else []
        kind = type(obj.geometry).__name__
        if k >= len(geoms) or mj.geom_type[geoms[k]] != MJ_TYPE.get(kind):
            raise SystemExit(
                f"shape {obj.name} ({kind}) has no matching MuJoCo geom on body "
                f"{link!r}: geometry differs, no comparison possible"
            )
        out.append(int(geoms[k]))
    mj.geom_contype[:] = 1  # mink keeps a pair only if contype & conaffinity
    mj.geom_conaffinity[:] = 1
    return out


def qpos_of(robot: wb.Robot, mj: mujoco.MjModel, q: np.ndarray) -> np.ndarray:
    """MuJoCo's qpos for wholebody's q, joint by name (continuous joints: cos, sin)."""
    qpos = mj.qpos0.copy()
    pm = robot.model
    for j in range(1, pm.njoints):
        jid = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, pm.names[j])
        if jid < 0:
            continue  # the planar base: welded to the world in MuJoCo
        i = pm.idx_qs[j]
        angle = math.atan2(q[i + 1], q[i]) if pm.nqs[j] == 2 else q[i]
        qpos[mj.jnt_qposadr[jid]] = angle
    return qpos


def postures(robot: wb.Robot, n: int) -> list[np.ndarray]:
    """Random postures (seed 0), the planar base at the origin with heading 0."""
    rng, root = np.random.default_rng(0), robot.model.idx_qs[1]
    out = []
    for _ in range(n):
        q = robot.random_configuration(rng, margin=0.2, base_range=0.0)
        q[root : root + 4] = (0.0, 0.0, 1.0, 0.0)
        out.append(q)
    return out


def distance_gap(
    model: CollisionModel,
    mj: mujoco.MjModel,
    data: mujoco.MjData,
    gmap: list[int],
    state: wb.RobotState,
    found: set,
) -> float:
    """Largest |d_wholebody - d_mujoco| (m) over the pairs both find within DETECTION."""
    fromto, gap = np.empty(6), 0.0
    for p in model.distances(state, DETECTION):
        i, k = (model.geometry.getGeometryId(n) for n in p.name.split("|"))
        ga, gb = sorted((gmap[i], gmap[k]))
        if (ga, gb) in found:
            d = mujoco.mj_geomDistance(mj, data, ga, gb, DETECTION, fromto)
            gap = max(gap, abs(d - p.distance))
    return gap


def run(n: int) -> None:
    robot = wb.load_robot("mobile_humanoid")
    model = CollisionModel(robot, shapes={"left_hand": "urdf", "right_hand": "urdf"})
    task = wb.CollisionAvoidance(robot, model, safety=SAFETY, influence=DETECTION)
    mj = load_mujoco(Path(robot.config.urdf))
    gmap = geom_map(model, mj)
    limit = CollisionAvoidanceLimit(
        mj,
        [([gmap[i]], [gmap[k]]) for i, k in model.pairs],
        minimum_distance_from_collisions=SAFETY,
        collision_detection_distance=DETECTION,
    )
    config = Configuration(mj)
    kept = set(limit.geom_id_pairs)
    dropped = [
        model.pair_name(i, k)
        for i, k in model.pairs
        if tuple(sorted((gmap[i], gmap[k]))) not in kept
    ]
    qs = postures(robot, n)
    keys = ("wb", "kernel", "mink", "n_wb", "n_mink", "gap")
    stats: dict[str, list[float]] = {k: [] for k in keys}
    rows = np.empty((task.max_rows, robot.nu))
    buffers = (rows, np.empty((len(model.pairs), RESULT_WIDTH)), np.empty(len(model.pairs), int))
    external = np.empty((0, RESULT_WIDTH))

    def kernel(q: np.ndarray) -> None:
        robot.update(q)
        J, oMf = robot.kinematics.views()
        collision_rows(J, oMf, model.packed, external, DETECTION, *buffers)

    for q in qs[:5]:  # warm-up (numba, caches)
        task.compute(robot.update(q), DT)
        kernel(q)
        config.update(qpos_of(robot, mj, q))
        limit.compute_qp_inequalities(config, DT)
    with threadpool_limits(1):
        for q in qs:
            qpos = qpos_of(robot, mj, q)
            t0 = time.perf_counter()
            task.compute(robot.update(q), DT)
            t1 = time.perf_counter()
            kernel(q)
            t2 = time.perf_counter()
            config.update(qpos)
            h = limit.compute_qp_inequalities(config, DT).h
            t3 = time.perf_counter()
            found = {limit.geom_id_pairs[r] for r in np.flatnonzero(np.isfinite(h))}
            state = robot.update(q)
            stats["wb"].append(t1 - t0)
            stats["kernel"].append(t2 - t1)
            stats["mink"].append(t3 - t2)
            stats["n_wb"].append(len(model.distances(state, DETECTION)))
            stats["n_mink"].append(len(found))
            stats["gap"].append(distance_gap(model, mj, config.data, gmap, state, found))
    report(stats, len(model.pairs), len(limit.geom_id_pairs), dropped, n)


def report(
    stats: dict[str, list[float]], n_wb: int, n_mink: int, dropped: list[str], n: int
) -> None:
    print(f"{n} postures; pairs checked: wholebody {n_wb}, mink {n_mink}")
    if dropped:
        print(f"pairs mink drops (welded / parent-child bodies): {', '.join(dropped)}")
    print("| case | median us | p90 us | pairs within 5 cm (median) | per pair us |")
    print("|---|---|---|---|---|")
    rows = (
        ("wholebody CollisionAvoidance.compute", "wb", "n_wb"),
        ("wholebody update + collision_rows kernel", "kernel", "n_wb"),
        ("mink update + CollisionAvoidanceLimit", "mink", "n_mink"),
    )
    for label, key, count in rows:
        t = np.array(stats[key]) * 1e6
        med, p90, pairs = np.median(t), np.percentile(t, 90), np.median(stats[count])
        per = f"{med / pairs:.1f}" if pairs else "-"
        print(f"| {label} | {med:.0f} | {p90:.0f} | {pairs:.0f} | {per} |")
    ratio = np.median(stats["wb"]) / np.median(stats["mink"])
    kernel = np.median(stats["kernel"]) / np.median(stats["mink"])
    print(f"\nratio of medians wholebody/mink: {ratio:.2f} (the task), {kernel:.2f} (the kernel)")
    diff = int(np.sum(np.array(stats["n_wb"]) != np.array(stats["n_mink"])))
    print(f"postures where the counts within 5 cm differ: {diff}")
    print(f"largest distance difference (pairs both find): {max(stats['gap']):.2e} m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200, help="postures (default 200)")
    run(parser.parse_args().n)


if __name__ == "__main__":
    main()
