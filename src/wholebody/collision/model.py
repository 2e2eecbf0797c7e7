"""Collision geometry: the robot's links and the environment's obstacles, the pairs checked, and
each pair's distance with its witness points and their Jacobians.

**Geometry.** The robot's collision shapes come from its URDF through Pinocchio
(``buildGeomFromUrdf`` with coal; locked joints welded as in the model). ``robot.toml``'s
``[collision]`` may replace a link's shapes by bounding capsules or a sphere (in the link's
frame: a capsule per shape, a sphere per link), cheaper and smoother to distance. Obstacles
(:class:`Obstacle`: box, cylinder, sphere or capsule) are fixed in the world.

**Pairs** (:class:`CollisionModel` builds them once): every two robot shapes on different
joints, except shapes on *adjacent* links (one joint is the other's nearest ancestor that
carries a shape), pairs closer than ``safety`` at the home posture (in contact by design, a
shoulder cap in its socket: they are listed in :attr:`CollisionModel.excluded` with the
reason), and pairs ``[collision] exclude`` names; and every robot shape against every
obstacle. Names in ``exclude`` may be links or shapes.

**Distance and its rate.** For a pair at distance ``d`` with witness points ``p_a`` on shape
a and ``p_b`` on shape b, and ``n = (p_b - p_a) / d`` (coal's normal where the shapes touch or
overlap), moving the robot at ``u`` changes the distance at::

    d' = n^T (J_b(p_b) - J_a(p_a)) u,    J(p) = J_lin,j - [p - o_j]x J_ang,j

with ``J_lin,j, J_ang,j`` the world-aligned Jacobian of the joint ``j`` that carries the shape
(origin ``o_j``), in actuated columns; an obstacle's is zero. Units: m, m/s.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from wholebody.errors import DimensionError
from wholebody.robot import Robot, RobotState

__all__ = ["SHAPES", "CollisionModel", "Obstacle", "PairDistance"]

SHAPES = ("box", "cylinder", "sphere", "capsule")
"""Obstacle shapes: box ``size`` (x, y, z extents, m), cylinder and capsule ``radius`` and
``length`` along their z axis, sphere ``radius``."""


GJK_TOLERANCE = 1e-9
"""coal's GJK tolerance (m): at its default 1e-6 the witness points of two cylinders are off
by enough to make the distance's derivative wrong by 1e-4."""


@dataclass(frozen=True)
class Obstacle:
    """A shape fixed in the world: ``pose`` (4x4, world) of its centre; ``size`` (m) the box's
    extents, or ``(radius, length)`` of a cylinder or capsule (along the pose's z), or
    ``(radius,)`` of a sphere."""

    name: str
    shape: str
    size: tuple[float, ...]
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))

    def geometry(self) -> coal.CollisionGeometry:
        """The coal shape, checked."""
        counts = {"box": 3, "cylinder": 2, "capsule": 2, "sphere": 1}
        if self.shape not in counts:
            raise DimensionError(f"obstacle {self.name!r}: shape must be one of "
                                 f"{', '.join(SHAPES)}, got {self.shape!r}")  # fmt: skip
        size = tuple(float(s) for s in self.size)
        if len(size) != counts[self.shape] or not all(math.isfinite(s) and s > 0 for s in size):
            raise DimensionError(f"obstacle {self.name!r}: a {self.shape} needs "
                                 f"{counts[self.shape]} sizes > 0 (m), got "
                                 f"{self.size!r}")  # fmt: skip
        pose = np.asarray(self.pose, dtype=float)
        rigid = (pose.shape == (4, 4) and np.all(np.isfinite(pose))
                 and np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0))
                 and np.allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-9)
                 and np.linalg.det(pose[:3, :3]) > 0)  # fmt: skip
        if not rigid:
            raise DimensionError(f"obstacle {self.name!r}: pose must be a rigid 4x4 transform "
                                 "(a rotation and a translation, last row 0 0 0 1)")  # fmt: skip
        if self.shape == "box":
            return coal.Box(*size)
        if self.shape == "sphere":
            return coal.Sphere(size[0])
        return (coal.Cylinder if self.shape == "cylinder" else coal.Capsule)(size[0], size[1])


@dataclass(frozen=True)
class PairDistance:
    """One pair at one state: ``d`` (m, negative when the shapes overlap), the witness
    points (world, m), the unit normal from a to b, and ``row = n^T (J_b - J_a)`` (nu,):
    ``d' = row . u``."""

    name: str
    a: str
    b: str
    distance: float
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray
    row: np.ndarray


class CollisionModel:
    """The robot's collision shapes, the obstacles and the pairs to check (module docstring).

    Parameters
    ----------
    robot
        The robot; its ``robot.toml`` ``[collision]`` (simplified links, excluded pairs)
        applies.
    obstacles
        Shapes fixed in the world.
    safety
        ``d_s`` (m): pairs closer than this at the home posture are excluded (reported).
    self_collision
        Check pairs of robot shapes (else only robot against obstacles).
    exclude
        More pairs to leave out, each two names of links, shapes or obstacles.
    shapes
        More links to simplify (link -> ``"capsule"`` or ``"sphere"``), as ``[collision]
        shapes``.
    attached
        Carried objects: ``(frame, obstacle)``, the obstacle's pose relative to the frame;
        they move with it and count as robot shapes (a name of theirs must not be a link's).
    start
        The posture whose contacts are left out (default the home posture; where a carry
        starts: the grasp's contacts).
    """

    def __init__(self, robot: Robot, obstacles: Sequence[Obstacle] = (), *,
                 safety: float = 0.01, self_collision: bool = True,
                 exclude: Iterable[Sequence[str]] = (),
                 shapes: Mapping[str, str] | None = None,
                 attached: Sequence[tuple[str, Obstacle]] = (),
                 start: np.ndarray | None = None) -> None:  # fmt: skip
        if not (math.isfinite(safety) and safety >= 0):
            raise DimensionError(f"collision safety distance must be >= 0 m, got {safety}")
        self.robot = robot
        settings = robot.config.collision
        geom, _ = robot.geometry("collision")
        self.geometry = _simplified(geom, robot, {**settings.shapes, **(shapes or {})})
        for frame, obj in attached:  # a carried object: a robot shape on the frame's joint
            f = robot.frame(frame)
            shape = obj.geometry()
            placement = robot.model.frames[f.index].placement * pin.SE3(np.asarray(obj.pose))
            self.geometry.addGeometryObject(
                pin.GeometryObject(
                    obj.name, robot.model.frames[f.index].parentJoint, f.index, placement, shape
                )
            )
        self.n_robot = len(self.geometry.geometryObjects)
        names = [o.name for o in obstacles]
        taken = {o.name for o in self.geometry.geometryObjects}  # carried objects too
        taken |= {f.name for f in robot.model.frames}
        if len(set(names)) != len(names) or taken & set(names):
            raise DimensionError(f"obstacle names must be unique and not a link's or a "
                                 f"shape's, got {names}")  # fmt: skip
        if self.n_robot == 0:
            raise DimensionError(f"robot {robot.name!r} has no collision shapes in its URDF: "
                                 "nothing to keep apart")  # fmt: skip
        for obstacle in obstacles:
            shape = obstacle.geometry()
            placement = pin.SE3(np.asarray(obstacle.pose, dtype=float))
            self.geometry.addGeometryObject(pin.GeometryObject(obstacle.name, 0, 0, placement,
                                                               shape))  # fmt: skip
        self.obstacles = tuple(obstacles)
        self.excluded: dict[tuple[str, str], str] = {}
        base = [robot.model.getJointId(w) for w in robot.config.base.wheels]
        self._base_joints = set(base) | ({1} if robot.config.base.type != "fixed" else set())
        skip = _named_pairs(self, [*settings.exclude, *exclude])
        self.pairs = self._pairs(self_collision, skip)
        self._set_pairs()
        self._contacts(safety, robot.home() if start is None else start,
                       "home" if start is None else "start")  # fmt: skip
        self._set_pairs()
        self._radius, self._centre = _bounding_spheres(self.geometry)
        self._pair_index = np.array(self.pairs, dtype=np.intp).reshape(-1, 2)
        self._labels = [(self.pair_name(i, k), self.link(i), self.link(k)) for i, k in self.pairs]
        self._warned_meshes = False

    # ------------------------------------------------------------------ pairs
    def link(self, index: int) -> str:
        """The link (or obstacle) name of shape ``index``."""
        obj = self.geometry.geometryObjects[index]
        if index >= self.n_robot:
            return obj.name
        return self.robot.model.frames[obj.parentFrame].name

    def _pairs(self, self_collision: bool, skip: set[frozenset[str]]) -> list[tuple[int, int]]:
        objs = self.geometry.geometryObjects
        joints = [o.parentJoint for o in objs]
        carried = {j for j in joints[: self.n_robot]}
        pairs = []
        for i in range(len(objs)):
            for k in range(i + 1, len(objs)):
                if i >= self.n_robot:  # obstacle against obstacle
                    continue
                reason = self._skip_reason(i, k, joints, carried, skip, self_collision)
                if reason:
                    self.excluded[(objs[i].name, objs[k].name)] = reason
                else:
                    pairs.append((i, k))
        return pairs

    def _skip_reason(self, i: int, k: int, joints: list[int], carried: set[int],
                     skip: set[frozenset[str]], self_collision: bool) -> str:  # fmt: skip
        names = {self.geometry.geometryObjects[i].name, self.link(i)}
        other = {self.geometry.geometryObjects[k].name, self.link(k)}
        if any(frozenset((a, b)) in skip for a in names for b in other):
            return "excluded in [collision] or by the caller"
        if k >= self.n_robot:
            return ""
        if not self_collision:
            return "self-collision off"
        ji, jk = joints[i], joints[k]
        if ji == jk:
            return "same joint"
        if ji in self._base_joints and jk in self._base_joints:
            return "base and wheels"
        parents = self.robot.model.parents
        if (
            _carrier_parent(ji, parents, carried) == jk
            or _carrier_parent(jk, parents, carried) == ji
        ):
            return "adjacent links"
        return ""

    def _set_pairs(self) -> None:
        """Pinocchio's collision pairs and data for :attr:`pairs` (its pair p is
        ``self.pairs[p]``), with our GJK tolerance."""
        self.geometry.removeAllCollisionPairs()
        for i, k in self.pairs:
            self.geometry.addCollisionPair(pin.CollisionPair(i, k))
        self.data = pin.GeometryData(self.geometry)
        for request in self.data.distanceRequests:
            request.gjk_tolerance = GJK_TOLERANCE

    def _contacts(self, safety: float, q: np.ndarray, where: str) -> None:
        """Leave out the robot's own pairs (carried objects included) closer than ``safety``
        at the posture ``q`` (home, or the start of a carry)."""
        model = self.robot.model  # its own data: the robot's current state stays valid
        pin.updateGeometryPlacements(model, model.createData(), self.geometry, self.data,
                                     np.asarray(q, dtype=float))  # fmt: skip
        objs = self.geometry.geometryObjects
        keep = []
        for p, (i, k) in enumerate(self.pairs):
            if k >= self.n_robot:  # an obstacle: where the robot stands is the scenario's
                keep.append((i, k))
                continue
            d = float(pin.computeDistance(self.geometry, self.data, p).min_distance)
            if d < safety:
                self.excluded[(objs[i].name, objs[k].name)] = (
                    f"{d * 1e3:.1f} mm apart at the {where} posture (< safety "
                    f"{safety * 1e3:.0f} mm)"
                )
            else:
                keep.append((i, k))
        self.pairs = keep

    def pair_name(self, i: int, k: int) -> str:
        """``"shape_a|shape_b"``."""
        objs = self.geometry.geometryObjects
        return f"{objs[i].name}|{objs[k].name}"

    # ------------------------------------------------------------------ distances
    def distances(self, state: RobotState, within: float = math.inf) -> list[PairDistance]:
        """Every checked pair closer than ``within`` (m) at ``state``, with its row. A
        bounding-sphere test skips the pairs that cannot be that close."""
        model = self.robot.model
        pin.updateGeometryPlacements(model, state._data(), self.geometry, self.data)
        objs, oMg = self.geometry.geometryObjects, self.data.oMg
        centres = np.array([oMg[i].act(self._centre[i]) for i in range(len(objs))])
        ia, ib = self._pair_index[:, 0], self._pair_index[:, 1]
        gaps = (np.linalg.norm(centres[ib] - centres[ia], axis=1) - self._radius[ia]
                - self._radius[ib])  # fmt: skip
        out, jacobians = [], {}
        for p in np.flatnonzero(gaps < within):
            i, k = self.pairs[p]
            d, pa, pb, n = _result(pin.computeDistance(self.geometry, self.data, int(p)))
            if n is None:
                n = self._apart(centres[i], centres[k], self._labels[p][0])
            if d < within:
                row = (self._point_row(state, objs[k].parentJoint, pb, n, jacobians)
                       - self._point_row(state, objs[i].parentJoint, pa, n, jacobians))  # fmt: skip
                name, a, b = self._labels[p]
                out.append(PairDistance(name, a, b, d, pa, pb, n, row))
        return out

    def _apart(self, a: np.ndarray, b: np.ndarray, name: str) -> np.ndarray:
        """The direction from a's bounding-sphere centre to b's: the normal of two meshes in
        contact, where coal gives none (a warning, once per model)."""
        if not self._warned_meshes:
            self._warned_meshes = True
            warnings.warn(f"{name}: two meshes in contact have no separating direction; "
                          "pushing their centres apart (simplify them to capsules in "
                          "[collision] shapes for an exact one)", stacklevel=3)  # fmt: skip
        gap = b - a
        length = float(np.linalg.norm(gap))
        return gap / length if length > 0 else np.array([0.0, 0.0, 1.0])

    def _point_row(self, state: RobotState, joint: int, point: np.ndarray, n: np.ndarray,
                   cache: dict[int, np.ndarray]) -> np.ndarray:  # fmt: skip
        """``n^T J(p)`` (nu,): the rate along ``n`` of ``point`` fixed to ``joint`` (zero for
        the world), ``J(p) = J_lin - [r]x J_ang`` so ``n^T J(p) = n^T J_lin - (n x r)^T
        J_ang``; ``cache`` keeps each joint's Jacobian (actuated columns) for the call."""
        robot = self.robot
        if joint == 0:
            return np.zeros(robot.nu)
        data = state._data()
        J = cache.get(joint)
        if J is None:
            J = pin.getJointJacobian(robot.model, data, joint, pin.LOCAL_WORLD_ALIGNED)
            J = cache[joint] = J @ robot.actuation
        r = point - data.oMi[joint].translation
        # n x r written out: np.cross costs ten times this
        n_x_r = np.array([n[1] * r[2] - n[2] * r[1], n[2] * r[0] - n[0] * r[2],
                          n[0] * r[1] - n[1] * r[0]])  # fmt: skip
        return n @ J[:3] - n_x_r @ J[3:]

    def summary(self) -> str:
        """How many pairs are checked and why the others are not."""
        reasons: dict[str, int] = {}
        for reason in self.excluded.values():
            key = (
                f"closer than safety at {reason.split(' at the ')[1].split()[0]}"
                if (" posture (< safety" in reason)
                else reason
            )
            reasons[key] = reasons.get(key, 0) + 1
        skipped = ", ".join(f"{n} {r}" for r, n in sorted(reasons.items()))
        return (f"{len(self.pairs)} pairs checked ({self.n_robot} robot shapes, "
                f"{len(self.obstacles)} obstacles); not checked: {skipped or 'none'}")  # fmt: skip


def _result(res: coal.DistanceResult):
    """``(d, p_a, p_b, n)`` of a coal distance result (copies)."""
    pa, pb = res.getNearestPoint1().copy(), res.getNearestPoint2().copy()
    d = float(res.min_distance)
    gap = pb - pa
    length = float(np.linalg.norm(gap))
    if d > 1e-9 and length > 0:
        return d, pa, pb, gap / length
    n = np.asarray(res.normal, dtype=float).copy()
    if not (np.all(np.isfinite(n)) and abs(float(np.linalg.norm(n)) - 1.0) < 1e-6):
        return d, pa, pb, None  # two meshes in contact: coal has no direction
    return d, pa, pb, n


def _carrier_parent(joint: int, parents: Sequence[int], carried: set[int]) -> int:
    """The nearest ancestor joint of ``joint`` that carries a shape (0: the world)."""
    j = parents[joint]
    while j > 0 and j not in carried:
        j = parents[j]
    return j


def _named_pairs(model: CollisionModel, pairs: Iterable[Sequence[str]]) -> set[frozenset[str]]:
    """The excluded pairs as name sets, each name checked against the shapes and links."""
    known = {o.name for o in model.geometry.geometryObjects}
    known |= {model.link(i) for i in range(len(model.geometry.geometryObjects))}
    out = set()
    for pair in pairs:
        if len(pair) != 2:
            raise DimensionError(f"collision exclude: each entry must name two links or "
                                 f"shapes, got {pair!r}")  # fmt: skip
        unknown = [n for n in pair if n not in known]
        if unknown:
            raise DimensionError(f"collision exclude: unknown link or shape {unknown[0]!r}; "
                                 f"known: {', '.join(sorted(known))}")  # fmt: skip
        out.add(frozenset(pair))
    return out


def _bounding_spheres(geom: pin.GeometryModel) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each shape's bounding-sphere radius and centre in the shape's frame (from its AABB)."""
    radius, centre = [], []
    for obj in geom.geometryObjects:
        g = obj.geometry
        g.computeLocalAABB()
        radius.append(float(g.aabb_radius))
        centre.append(np.asarray(g.aabb_center, dtype=float).copy())
    return np.array(radius), centre


def _simplified(geom: pin.GeometryModel, robot: Robot,
                shapes: Mapping[str, str]) -> pin.GeometryModel:  # fmt: skip
    """``geom`` with the shapes of each link of ``shapes`` replaced by one bounding capsule or
    sphere of them (``[collision] shapes``; link -> ``"capsule"`` or ``"sphere"``; the key
    ``"*"`` for every link not named, ``"urdf"`` to keep a link's own)."""
    if not shapes:
        return geom
    out = pin.GeometryModel()
    by_link: dict[str, list[pin.GeometryObject]] = {}
    default = shapes.get("*", "urdf")
    for obj in geom.geometryObjects:
        link = robot.model.frames[obj.parentFrame].name
        if shapes.get(link, default) != "urdf":
            by_link.setdefault(link, []).append(obj)
        else:
            out.addGeometryObject(obj)
    missing = sorted(set(shapes) - set(by_link) - {"*"} - {k for k, v in shapes.items()
                                                           if v == "urdf"})  # fmt: skip
    if missing:
        raise DimensionError(f"[collision] shapes: link {missing[0]!r} has no collision shape "
                             "in the URDF")  # fmt: skip
    for link, objs in by_link.items():
        kind = shapes.get(link, default)
        if kind == "capsule":  # one per shape: a capsule around a box and a cylinder is long
            for obj in objs:
                out.addGeometryObject(_bounding(obj.name, [obj], kind))
        else:
            out.addGeometryObject(_bounding(link, objs, kind))
    return out


def _capsule_of_cylinder(obj: pin.GeometryObject) -> pin.GeometryObject:
    """The capsule of a cylinder's radius and length: it holds the cylinder."""
    g = obj.geometry
    capsule = coal.Capsule(g.radius, 2.0 * g.halfLength)
    return pin.GeometryObject(f"{obj.name}_capsule", obj.parentJoint, obj.parentFrame,
                              obj.placement, capsule)  # fmt: skip


def _hull_points(g: coal.CollisionGeometry, sides: int = 16) -> np.ndarray:
    """Points (shape frame) whose convex hull holds the shape: a box's corners, a cylinder's
    two rims as polygons of ``sides`` around the circle (the radius widened by
    ``1 / cos(pi / sides)``), else the corners of the shape's bounding box."""
    if isinstance(g, coal.Cylinder):
        r = g.radius / math.cos(math.pi / sides)
        a = np.linspace(0.0, 2.0 * math.pi, sides, endpoint=False)
        ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
        return np.vstack([np.column_stack([ring, np.full(sides, z)])
                          for z in (-g.halfLength, g.halfLength)])  # fmt: skip
    g.computeLocalAABB()
    lo, hi = np.asarray(g.aabb_local.min_), np.asarray(g.aabb_local.max_)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                     for z in (lo[2], hi[2])])  # fmt: skip


def _bounding(name: str, objs: list[pin.GeometryObject], kind: str) -> pin.GeometryObject:
    """One capsule (along the longest extent) or sphere holding the shapes (a box's corners,
    a cylinder's rims), placed in the frame of the joint that carries them; named
    ``{name}_{kind}``."""
    if kind == "capsule" and len(objs) == 1 and isinstance(objs[0].geometry, coal.Cylinder):
        return _capsule_of_cylinder(objs[0])
    corners = [_hull_points(obj.geometry) @ obj.placement.rotation.T + obj.placement.translation
               for obj in objs]  # fmt: skip
    pts = np.vstack(corners)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2.0
    first = objs[0]
    placement = pin.SE3(np.eye(3), centre)
    if kind == "sphere":
        shape = coal.Sphere(float(np.max(np.linalg.norm(pts - centre, axis=1))))
    elif kind == "capsule":
        axis = int(np.argmax(hi - lo))
        others = [a for a in range(3) if a != axis]
        radial = np.linalg.norm((pts - centre)[:, others], axis=1)
        radius = float(np.max(radial))
        # the segment reaches every corner within the radius: |z| - sqrt(r^2 - radial^2)
        reach = np.abs(pts[:, axis] - centre[axis]) - np.sqrt(np.maximum(radius**2 - radial**2,
                                                                          0.0))  # fmt: skip
        length = 2.0 * max(float(np.max(reach)), 0.0)
        R = np.eye(3)[:, [others[0], others[1], axis]]  # the capsule's z along the axis
        if np.linalg.det(R) < 0:
            R[:, 0] *= -1.0
        placement = pin.SE3(R, centre)
        shape = coal.Capsule(radius, length)
    else:
        raise DimensionError(f"[collision] shapes.{name}: expected \"capsule\" or \"sphere\", "
                             f"got {kind!r}")  # fmt: skip
    return pin.GeometryObject(f"{name}_{kind}", first.parentJoint, first.parentFrame, placement,
                              shape)  # fmt: skip
