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

**Distance and its rate.** For a pair at signed distance ``d`` (negative where the shapes
overlap) with witness points ``p_a`` on shape a and ``p_b`` on shape b and the unit normal
``n`` from a to b (``p_b - p_a = d n``), moving the robot at ``u`` changes the distance at::

    d' = n^T (J_b(p_b) - J_a(p_a)) u

with ``J(p)`` the world-aligned Jacobian of the point p fixed to the shape, in actuated
columns; an obstacle's is zero. Units: m, m/s. Both come from one kernel,
:func:`wholebody.kernels.collision.collision_rows` (spheres, capsules, boxes and cylinders:
:mod:`wholebody.kernels.distance`), on the model packed once (:attr:`CollisionModel.packed`);
a pair with a mesh (or any other coal shape) is measured by coal first and handed to it
(:meth:`CollisionModel.external`).
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
from wholebody.kernels.collision import (
    CENTRE,
    EXTERNAL,
    RADIUS,
    RESULT_WIDTH,
    SHAPE_WIDTH,
    SIZE,
    PackedCollision,
    collision_rows,
    nearest_pairs,
)
from wholebody.kernels.distance import BOX, CAPSULE, CYLINDER, SPHERE
from wholebody.robot import Robot, RobotState
from wholebody.robot.parts import Frame

__all__ = ["SHAPES", "CollisionModel", "Obstacle", "PairDistance"]

SHAPES = ("box", "cylinder", "sphere", "capsule")
"""Obstacle shapes: box ``size`` (x, y, z extents, m), cylinder and capsule ``radius`` and
``length`` along their z axis, sphere ``radius``."""


CONTACT_SLACK = 1e-9
"""m: how far beyond the safety distance a pair at the home (or start) posture still counts as
in contact there."""

GJK_TOLERANCE = 1e-9
"""coal's GJK tolerance (m), for the pairs with a mesh: at its default 1e-6 the witness points
of two curved shapes are off by enough to make the distance's derivative wrong by 1e-4."""


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
            raise DimensionError(
                f"obstacle {self.name!r}: shape must be one of "
                f"{', '.join(SHAPES)}, got {self.shape!r}"
            )
        size = tuple(float(s) for s in self.size)
        if len(size) != counts[self.shape] or not all(math.isfinite(s) and s > 0 for s in size):
            raise DimensionError(
                f"obstacle {self.name!r}: a {self.shape} needs "
                f"{counts[self.shape]} sizes > 0 (m), got "
                f"{self.size!r}"
            )
        pose = np.asarray(self.pose, dtype=float)
        rigid = (
            pose.shape == (4, 4)
            and np.all(np.isfinite(pose))
            and np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0))
            and np.allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-9)
            and np.linalg.det(pose[:3, :3]) > 0
        )
        if not rigid:
            raise DimensionError(
                f"obstacle {self.name!r}: pose must be a rigid 4x4 transform "
                "(a rotation and a translation, last row 0 0 0 1)"
            )
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

    def __init__(
        self,
        robot: Robot,
        obstacles: Sequence[Obstacle] = (),
        *,
        safety: float = 0.01,
        self_collision: bool = True,
        exclude: Iterable[Sequence[str]] = (),
        shapes: Mapping[str, str] | None = None,
        attached: Sequence[tuple[str, Obstacle]] = (),
        start: np.ndarray | None = None,
    ) -> None:
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
            raise DimensionError(
                f"obstacle names must be unique and not a link's or a shape's, got {names}"
            )
        if self.n_robot == 0:
            raise DimensionError(
                f"robot {robot.name!r} has no collision shapes in its URDF: nothing to keep apart"
            )
        for obstacle in obstacles:
            shape = obstacle.geometry()
            placement = pin.SE3(np.asarray(obstacle.pose, dtype=float))
            self.geometry.addGeometryObject(
                pin.GeometryObject(obstacle.name, 0, 0, placement, shape)
            )
        self.obstacles = tuple(obstacles)
        self._table = _shape_table(self.geometry, robot, self.n_robot)
        self._request = coal.DistanceRequest()  # for the pairs with a mesh
        self._request.gjk_tolerance = GJK_TOLERANCE
        self._warned_meshes = False
        self.excluded: dict[tuple[str, str], str] = {}
        base = [robot.model.getJointId(w) for w in (*robot.base.wheel_joints, *robot.base.held)]
        self._base_joints = set(base) | ({1} if robot.config.base.type != "fixed" else set())
        skip = _named_pairs(self, [*settings.exclude, *exclude])
        self.pairs = self._pairs(self_collision, skip)
        self._contacts(
            safety, robot.home() if start is None else start, "home" if start is None else "start"
        )
        self._set_pairs()
        self._labels = [(self.pair_name(i, k), self.link(i), self.link(k)) for i, k in self.pairs]
        self.packed, self._coal_pairs = self._pack(self.pairs)
        """The model as the kernels read it (:mod:`wholebody.kernels.collision`)."""
        self._found = np.empty((len(self.pairs), RESULT_WIDTH))
        self._index = np.empty(len(self.pairs), dtype=np.int64)
        self._rows = np.empty((len(self.pairs), robot.nu))

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

    def _skip_reason(
        self,
        i: int,
        k: int,
        joints: list[int],
        carried: set[int],
        skip: set[frozenset[str]],
        self_collision: bool,
    ) -> str:
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
        at the posture ``q`` (home, or the start of a carry), measured as :meth:`distances`
        does; a pair at ``safety`` within ``CONTACT_SLACK`` counts (two links 1 cm apart by
        design, with a safety of 1 cm: the constraint would hold them there)."""
        model = self.robot.model  # its own data: the robot's current state stays valid
        data = model.createData()
        pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
        oMf = _frame_placements(data)
        packed, coal_pairs = self._pack(self.pairs)
        found = np.empty((len(self.pairs), RESULT_WIDTH))
        index = np.empty(len(self.pairs), dtype=np.int64)
        within = safety + CONTACT_SLACK
        external = self._coal_distances(coal_pairs, oMf, within, warn=False)  # only d counts
        n, _ = nearest_pairs(oMf, packed, external, within, found, index)
        close = {int(index[r]): float(found[r, 0]) for r in range(n)}
        objs = self.geometry.geometryObjects
        keep = []
        for p, (i, k) in enumerate(self.pairs):
            if k >= self.n_robot or p not in close:  # an obstacle: the scenario's business
                keep.append((i, k))
                continue
            self.excluded[(objs[i].name, objs[k].name)] = (
                f"{close[p] * 1e3:.1f} mm apart at the {where} posture (< safety "
                f"{safety * 1e3:.0f} mm)"
            )
        self.pairs = keep

    def pair_name(self, i: int, k: int) -> str:
        """``"shape_a|shape_b"``."""
        objs = self.geometry.geometryObjects
        return f"{objs[i].name}|{objs[k].name}"

    # ------------------------------------------------------------------ distances
    def distances(self, state: RobotState, within: float = math.inf) -> list[PairDistance]:
        """Every checked pair closer than ``within`` (m) at ``state``, closest first, with its
        row: the kernel :func:`~wholebody.kernels.collision.collision_rows` (bounding spheres
        first, then the exact distance), after coal for the pairs with a mesh."""
        state.require_valid()
        J, oMf = self.robot.kinematics.views()
        within = float(within)
        external = self.external(oMf, within)
        n, _ = collision_rows(
            J, oMf, self.packed, external, within, self._rows, self._found, self._index
        )
        found, rows = self._found[:n].copy(), self._rows[:n].copy()  # the pairs' own arrays
        out = []
        for r in range(n):
            name, a, b = self._labels[self._index[r]]
            f = found[r]
            out.append(PairDistance(name, a, b, float(f[0]), f[1:4], f[4:7], f[7:10], rows[r]))
        return out

    def external(self, oMf: np.ndarray, within: float) -> np.ndarray:
        """The kernels' ``external`` rows at the frame placements ``oMf`` (nframes, 12): coal's
        results (``d, p_a, p_b, n``) for the pairs with a mesh, ``d = inf`` where they are
        farther apart than ``within`` (m) by their bounding spheres; none without meshes."""
        return self._coal_distances(self._coal_pairs, oMf, within)

    def _pack(self, pairs: list[tuple[int, int]]) -> tuple[PackedCollision, np.ndarray]:
        """The kernels' model for ``pairs``, and the pairs coal computes (a shape the kernel
        does not handle; (C, 2) shape indices), in the order of their rows in ``external``."""
        shapes, kinds, support = self._table
        table = np.zeros((len(pairs), 3), dtype=np.int64)
        coal_pairs = []
        for p, (i, k) in enumerate(pairs):
            slot = -1
            if kinds[i, 0] == EXTERNAL or kinds[k, 0] == EXTERNAL:
                slot = len(coal_pairs)
                coal_pairs.append((i, k))
            table[p] = (i, k, slot)
        kin = self.robot.kinematics
        act = np.ascontiguousarray(np.stack([kin.act_k, kin.act_j]))
        packed = PackedCollision(shapes, kinds, support, table, act, kin.act_a.copy())
        return packed, np.array(coal_pairs, dtype=np.intp).reshape(-1, 2)

    def _coal_distances(
        self, coal_pairs: np.ndarray, oMf: np.ndarray, within: float, warn: bool = True
    ) -> np.ndarray:
        """The results (rows ``d, p_a, p_b, n``, world) of the pairs coal computes (shape
        indices, (C, 2)), at the frame placements ``oMf``; ``d = inf`` where the bounding
        spheres are farther apart than ``within`` (m). ``warn``: about meshes in contact
        (:meth:`_apart`)."""
        out = np.empty((len(coal_pairs), RESULT_WIDTH))
        if not len(coal_pairs):
            return out
        shapes, kinds, _ = self._table
        R = shapes[:, :9].reshape(-1, 3, 3).transpose(0, 2, 1)  # each rotation (column-major)
        t = shapes[:, 9:12]
        robot = kinds[:, 1] >= 0
        f = kinds[robot, 1]
        Rf = oMf[f, :9].reshape(-1, 3, 3).transpose(0, 2, 1)
        R, t = R.copy(), t.copy()
        R[robot] = Rf @ R[robot]
        t[robot] = np.einsum("fij,fj->fi", Rf, t[robot]) + oMf[f, 9:12]
        centre = np.einsum("sij,sj->si", R, shapes[:, CENTRE : CENTRE + 3]) + t
        a, b = coal_pairs[:, 0], coal_pairs[:, 1]
        gap = np.linalg.norm(centre[b] - centre[a], axis=1) - shapes[a, RADIUS] - shapes[b, RADIUS]
        out[:, 0] = np.inf
        objs = self.geometry.geometryObjects
        for s in np.flatnonzero(gap < within + 1e-9):
            i, k = int(a[s]), int(b[s])
            res = coal.DistanceResult()
            A, B = coal.Transform3s(R[i], t[i]), coal.Transform3s(R[k], t[k])
            coal.distance(objs[i].geometry, A, objs[k].geometry, B, self._request, res)
            d, pa, pb, n = _result(res)
            if n is None:
                n = self._apart(centre[i], centre[k], self.pair_name(i, k), warn)
            out[s, 0], out[s, 1:4], out[s, 4:7], out[s, 7:10] = d, pa, pb, n
        return out

    def _apart(self, a: np.ndarray, b: np.ndarray, name: str, warn: bool) -> np.ndarray:
        """The direction from a's bounding-sphere centre to b's: the normal of two meshes in
        contact, where coal gives none (a warning if ``warn``, once per model)."""
        if warn and not self._warned_meshes:
            self._warned_meshes = True
            warnings.warn(
                f"{name}: two meshes in contact have no separating direction; "
                "pushing their centres apart (simplify them to capsules in "
                "[collision] shapes for an exact one)",
                stacklevel=3,
            )
        gap = b - a
        length = float(np.linalg.norm(gap))
        return gap / length if length > 0 else np.array([0.0, 0.0, 1.0])

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
        return (
            f"{len(self.pairs)} pairs checked ({self.n_robot} robot shapes, "
            f"{len(self.obstacles)} obstacles); not checked: {skipped or 'none'}"
        )


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
            raise DimensionError(
                f"collision exclude: each entry must name two links or shapes, got {pair!r}"
            )
        unknown = [n for n in pair if n not in known]
        if unknown:
            raise DimensionError(
                f"collision exclude: unknown link or shape {unknown[0]!r}; "
                f"known: {', '.join(sorted(known))}"
            )
        out.add(frozenset(pair))
    return out


def _shape_table(
    geom: pin.GeometryModel, robot: Robot, n_robot: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shapes as :class:`~wholebody.kernels.collision.PackedCollision` holds them:
    ``(shapes, kinds, support)``. A robot shape is fixed to its parent frame (the placement
    relative to it ``frame.placement^-1 * placement``), an obstacle to the world; a shape
    other than a sphere, capsule, box or cylinder (a mesh, a swept shape) is EXTERNAL, left
    to coal."""
    model = robot.model
    objs = geom.geometryObjects
    shapes = np.zeros((len(objs), SHAPE_WIDTH))
    kinds = np.zeros((len(objs), 2), dtype=np.int64)
    frames = []
    for s, obj in enumerate(objs):
        kind, size, centre, radius = _primitive(obj.geometry)
        if s < n_robot:
            f = _frame_of(model, obj)
            local = model.frames[f].placement.inverse() * obj.placement
            frames.append(Frame(model.frames[f].name, f, int(obj.parentJoint)))
        else:
            f, local = -1, obj.placement
        shapes[s, :9] = local.rotation.ravel(order="F")
        shapes[s, 9:12] = local.translation
        shapes[s, SIZE : SIZE + 3] = size
        shapes[s, CENTRE : CENTRE + 3] = centre
        shapes[s, RADIUS] = radius
        kinds[s] = (kind, f)
    support = np.zeros((len(objs), model.nv), dtype=np.int64)
    support[:n_robot] = robot.kinematics.support(frames)
    return shapes, kinds, support


def _primitive(g: coal.CollisionGeometry) -> tuple[int, tuple[float, ...], np.ndarray, float]:
    """A coal shape's kernel kind, sizes (m: radius or half extents, half lengths), and its
    bounding sphere's centre (its own axes) and radius (m)."""
    plain = isinstance(g, coal.ShapeBase) and g.getSweptSphereRadius() == 0.0
    origin = np.zeros(3)
    if type(g) is coal.Sphere and plain:
        return SPHERE, (g.radius, 0.0, 0.0), origin, g.radius
    if type(g) is coal.Capsule and plain:
        return CAPSULE, (g.radius, g.halfLength, 0.0), origin, g.radius + g.halfLength
    if type(g) is coal.Box and plain:
        half = np.asarray(g.halfSide, dtype=float)
        return BOX, tuple(half), origin, float(np.linalg.norm(half))
    if type(g) is coal.Cylinder and plain:
        radius = math.hypot(g.radius, g.halfLength)
        return CYLINDER, (g.radius, g.halfLength, 0.0), origin, radius
    g.computeLocalAABB()
    centre = np.asarray(g.aabb_center, dtype=float).copy()
    return EXTERNAL, (0.0, 0.0, 0.0), centre, float(g.aabb_radius)


def _frame_of(model: pin.Model, obj: pin.GeometryObject) -> int:
    """The frame a robot shape is fixed to: its parent frame, or where that frame is not on
    the shape's joint, the first frame that is."""
    if model.frames[obj.parentFrame].parentJoint == obj.parentJoint:
        return int(obj.parentFrame)
    for f, frame in enumerate(model.frames):
        if frame.parentJoint == obj.parentJoint:
            return f
    raise DimensionError(f"collision shape {obj.name!r}: no frame on its joint")


def _frame_placements(data: pin.Data) -> np.ndarray:
    """The frame placements (nframes, 12): rotation column-major, then translation."""
    out = np.empty((len(data.oMf), 12))
    for f, M in enumerate(data.oMf):
        out[f, :9] = M.rotation.ravel(order="F")
        out[f, 9:] = M.translation
    return out


def _simplified(
    geom: pin.GeometryModel, robot: Robot, shapes: Mapping[str, str]
) -> pin.GeometryModel:
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
    missing = sorted(
        set(shapes) - set(by_link) - {"*"} - {k for k, v in shapes.items() if v == "urdf"}
    )
    if missing:
        raise DimensionError(
            f"[collision] shapes: link {missing[0]!r} has no collision shape in the URDF"
        )
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
    return pin.GeometryObject(
        f"{obj.name}_capsule", obj.parentJoint, obj.parentFrame, obj.placement, capsule
    )


def _hull_points(g: coal.CollisionGeometry, sides: int = 16) -> np.ndarray:
    """Points (shape frame) whose convex hull holds the shape: a box's corners, a cylinder's
    two rims as polygons of ``sides`` around the circle (the radius widened by
    ``1 / cos(pi / sides)``), else the corners of the shape's bounding box."""
    if isinstance(g, coal.Cylinder):
        r = g.radius / math.cos(math.pi / sides)
        a = np.linspace(0.0, 2.0 * math.pi, sides, endpoint=False)
        ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
        return np.vstack(
            [np.column_stack([ring, np.full(sides, z)]) for z in (-g.halfLength, g.halfLength)]
        )
    g.computeLocalAABB()
    lo, hi = np.asarray(g.aabb_local.min_), np.asarray(g.aabb_local.max_)
    return np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )


def _bounding(name: str, objs: list[pin.GeometryObject], kind: str) -> pin.GeometryObject:
    """One capsule (along the longest extent) or sphere holding the shapes (a box's corners,
    a cylinder's rims), placed in the frame of the joint that carries them; named
    ``{name}_{kind}``."""
    if kind == "capsule" and len(objs) == 1 and isinstance(objs[0].geometry, coal.Cylinder):
        return _capsule_of_cylinder(objs[0])
    corners = [
        _hull_points(obj.geometry) @ obj.placement.rotation.T + obj.placement.translation
        for obj in objs
    ]
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
        reach = np.abs(pts[:, axis] - centre[axis]) - np.sqrt(
            np.maximum(radius**2 - radial**2, 0.0)
        )
        length = 2.0 * max(float(np.max(reach)), 0.0)
        R = np.eye(3)[:, [others[0], others[1], axis]]  # the capsule's z along the axis
        if np.linalg.det(R) < 0:
            R[:, 0] *= -1.0
        placement = pin.SE3(R, centre)
        shape = coal.Capsule(radius, length)
    else:
        raise DimensionError(
            f'[collision] shapes.{name}: expected "capsule" or "sphere", got {kind!r}'
        )
    return pin.GeometryObject(
        f"{name}_{kind}", first.parentJoint, first.parentFrame, placement, shape
    )
