"""The collision kernels (:mod:`wholebody.kernels.distance`, :mod:`wholebody.kernels.collision`)
against independent oracles: coal (``coal.distance``, GJK tolerance 1e-9 as the model sets it)
and the shapes' analytic support functions ``h(u) = max_{x in shape} u . x``, which certify
an answer without trusting any algorithm:

- apart, witness points ``p_a`` in a and ``p_b`` in b with ``p_b - p_a = d n``, ``p_a``
  extreme along ``n`` in a and ``p_b`` along ``-n`` in b, are the closest points: ``d`` is
  then at once an upper bound (``|p_b - p_a|``) and a lower bound (the gap between the two
  supporting planes) of the distance;
- overlapping, moving b by ``h_a(n) + h_b(-n)`` along ``n`` separates the shapes: the depth
  reported must be that translation along the normal reported, and no direction may need
  less (coal's normal, or a local search);

and the rows against finite differences of the distance on the paper's robot.
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import minimize

import wholebody as wb
from wholebody.collision import CollisionModel, Obstacle
from wholebody.kernels.collision import RESULT_WIDTH, collision_rows, nearest_pairs
from wholebody.kernels.distance import (
    BOX,
    CAPSULE,
    CYLINDER,
    EPA_TOLERANCE,
    SPHERE,
    shape_distance,
    workspace,
)

KINDS = {SPHERE: "sphere", CAPSULE: "capsule", BOX: "box", CYLINDER: "cylinder"}
COMBOS = [(a, b) for a in KINDS for b in KINDS]
CERTIFIED = 1e-9  # m: the support-function certificate (GJK on a cylinder: ~5e-10 at worst)
COAL_GJK = 2e-9  # coal's GJK at tolerance 1e-9: relative to the distance (1.5e-9 seen at 1.3 m)
COAL_TOUCH = 1e-6  # coal's GJK on a cylinder touching another shape (1.8e-7 seen)
COAL_EPA = 2e-6  # coal's EPA tolerance (1e-6), in the depth
TRIALS = 40


def _size(kind: int, rng: np.random.Generator) -> np.ndarray:
    if kind == SPHERE:
        return np.array([rng.uniform(0.02, 0.1), 0.0, 0.0])
    if kind == BOX:
        return rng.uniform(0.01, 0.15, 3)
    return np.array([rng.uniform(0.02, 0.08), rng.uniform(0.02, 0.2), 0.0])


def _coal_shape(kind: int, s: np.ndarray) -> coal.CollisionGeometry:
    if kind == SPHERE:
        return coal.Sphere(s[0])
    if kind == CAPSULE:
        return coal.Capsule(s[0], 2 * s[1])
    if kind == BOX:
        return coal.Box(*(2 * s))
    return coal.Cylinder(s[0], 2 * s[1])


def _pose(rng: np.random.Generator, spread: float) -> tuple[np.ndarray, np.ndarray]:
    """A random rotation and a position near a point of the robot's workspace (m)."""
    return pin.exp3(rng.normal(size=3) * 2), rng.normal(size=3) * spread + (1.0, -0.5, 0.9)


def _placement(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.concatenate([R.ravel(order="F"), t])


def _h(kind: int, s: np.ndarray, R: np.ndarray, t: np.ndarray, u: np.ndarray) -> float:
    """The support function of the whole shape (world, m) along ``u`` (unit)."""
    ul = R.T @ u
    if kind == SPHERE:
        value = s[0] * np.linalg.norm(ul)
    elif kind == CAPSULE:
        value = s[1] * abs(ul[2]) + s[0] * np.linalg.norm(ul)
    elif kind == BOX:
        value = np.abs(ul) @ s
    else:
        value = s[0] * np.linalg.norm(ul[:2]) + s[1] * abs(ul[2])
    return float(value + t @ u)


def _outside(kind: int, s: np.ndarray, R: np.ndarray, t: np.ndarray, p: np.ndarray) -> float:
    """How far (m) the point ``p`` lies outside the shape (<= 0: in it), per axis bound."""
    x = R.T @ (p - t)
    if kind == SPHERE:
        return float(np.linalg.norm(x) - s[0])
    if kind == CAPSULE:
        return float(np.linalg.norm([x[0], x[1], max(abs(x[2]) - s[1], 0.0)]) - s[0])
    if kind == BOX:
        return float(np.max(np.abs(x) - s))
    return float(max(np.hypot(x[0], x[1]) - s[0], abs(x[2]) - s[1]))


class Pair:
    """Two random shapes and their poses; the kernel's and coal's answers."""

    def __init__(self, ka: int, kb: int, rng: np.random.Generator) -> None:
        self.ka, self.kb = ka, kb
        self.sa, self.sb = _size(ka, rng), _size(kb, rng)
        self.Ra, self.ta = _pose(rng, 0.0)
        self.Rb, self.tb = _pose(rng, 0.15)

    def moved(self, offset: np.ndarray) -> Pair:
        other = object.__new__(Pair)
        other.__dict__.update(self.__dict__)
        other.tb = self.tb + offset
        return other

    def kernel(self, far: float = math.inf) -> np.ndarray:
        out = np.empty(RESULT_WIDTH)
        Ma, Mb = _placement(self.Ra, self.ta), _placement(self.Rb, self.tb)
        shape_distance(self.ka, self.sa, Ma, self.kb, self.sb, Mb, far, workspace(), out)
        return out

    def coal(self) -> coal.DistanceResult:
        request, result = coal.DistanceRequest(), coal.DistanceResult()
        request.gjk_tolerance = 1e-9
        a, b = _coal_shape(self.ka, self.sa), _coal_shape(self.kb, self.sb)
        Ta, Tb = coal.Transform3s(self.Ra, self.ta), coal.Transform3s(self.Rb, self.tb)
        coal.distance(a, Ta, b, Tb, request, result)
        return result

    def translation(self, n: np.ndarray) -> float:
        """``h_a(n) + h_b(-n)``: how far b moves along ``n`` to clear a (negative: apart)."""
        n = n / np.linalg.norm(n)
        a = _h(self.ka, self.sa, self.Ra, self.ta, n)
        return a + _h(self.kb, self.sb, self.Rb, self.tb, -n)


def _pairs(ka: int, kb: int, seed: int) -> list[Pair]:
    rng = np.random.default_rng(seed)
    return [Pair(ka, kb, rng) for _ in range(TRIALS)]


@pytest.mark.parametrize(("ka", "kb"), COMBOS, ids=[f"{KINDS[a]}-{KINDS[b]}" for a, b in COMBOS])
def test_separated_pairs_are_the_closest_points_and_agree_with_coal(ka, kb):
    """Apart: the certificate to 1e-9 m, the distance to coal's to 1e-9 m, the witness
    points to coal's to 1e-9 m where both are exact (no cylinder; on a cylinder's curved side
    coal's GJK at 1e-9 leaves its witness points up to 1e-5 m off, ours are certified)."""
    checked = 0
    for pair in _pairs(ka, kb, 1 + 4 * ka + kb):
        d, pa, pb, n = (lambda r: (r[0], r[1:4], r[4:7], r[7:10]))(pair.kernel())
        if d <= 1e-6:
            continue
        checked += 1
        res = pair.coal()
        assert d == pytest.approx(res.min_distance, abs=COAL_GJK * max(1.0, d))
        assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(pb - pa, d * n, atol=1e-12)
        assert _outside(ka, pair.sa, pair.Ra, pair.ta, pa) <= 1e-12
        assert _outside(kb, pair.sb, pair.Rb, pair.tb, pb) <= 1e-12
        assert d + pair.translation(n) <= CERTIFIED  # both supporting planes d apart
        if CYLINDER not in (ka, kb):
            np.testing.assert_allclose(pa, res.getNearestPoint1(), atol=1e-9)
            np.testing.assert_allclose(pb, res.getNearestPoint2(), atol=1e-9)
        assert pair.kernel(far=0.9 * d)[0] in (d, math.inf)  # beyond far: inf if GJK saw it
        assert pair.kernel(far=1.1 * d)[0] == d
    assert checked >= 15


@pytest.mark.parametrize(("ka", "kb"), COMBOS, ids=[f"{KINDS[a]}-{KINDS[b]}" for a, b in COMBOS])
def test_touching_and_nearly_touching_pairs_keep_their_distance_and_normal(ka, kb):
    """A separated pair with b moved by ``-(d - gap) n``, which leaves it ``gap`` apart along
    the same normal (gap 0, 10 nm, 1 um): the distance within 1e-9 m (coal: 1e-9 m, 1e-6 m
    with a cylinder), and a normal that still separates the shapes to 2e-8 m (GJK's normal
    is the direction of a tiny gap: EPA's facet near contact)."""
    checked = 0
    for apart in _pairs(ka, kb, 100 + 4 * ka + kb):
        first = apart.kernel()
        if first[0] <= 1e-3:
            continue
        for gap in (0.0, 1e-8, 1e-6):
            pair = apart.moved(-(first[0] - gap) * first[7:10])
            d, n = pair.kernel()[0], pair.kernel()[7:10]
            checked += 1
            assert d == pytest.approx(gap, abs=1e-9)
            coal_gap = COAL_TOUCH if CYLINDER in (ka, kb) else 1e-9
            assert pair.coal().min_distance == pytest.approx(gap, abs=coal_gap)
            assert pair.translation(n) <= -gap + 2e-8
            assert n @ first[7:10] > 0.0
    assert checked >= 30


@pytest.mark.parametrize(("ka", "kb"), COMBOS, ids=[f"{KINDS[a]}-{KINDS[b]}" for a, b in COMBOS])
def test_overlapping_pairs_report_the_least_translation_that_separates_them(ka, kb):
    """Overlapping: ``-d`` is the translation along ``n`` that separates the shapes (within
    EPA's tolerance), no direction needs less (coal's normal, a local search from it), and
    the depth is coal's to its EPA tolerance (1e-6), except a sphere whose centre is inside
    a cylinder, which coal pushes out radially even where a cap is nearer."""
    checked = 0
    for pair in _pairs(ka, kb, 200 + 4 * ka + kb):
        d, pa, pb, n = (lambda r: (r[0], r[1:4], r[4:7], r[7:10]))(pair.kernel())
        if d >= -1e-6:
            continue
        checked += 1
        np.testing.assert_allclose(pb - pa, d * n, atol=1e-12)
        assert pair.translation(n) == pytest.approx(-d, abs=1e-9 + EPA_TOLERANCE)
        res = pair.coal()
        nc = np.asarray(res.normal, dtype=float)
        assert -d <= pair.translation(nc) + 1e-9 + EPA_TOLERANCE
        options = {"xatol": 1e-10, "fatol": 1e-13}
        search = minimize(pair.translation, nc, method="Nelder-Mead", options=options)
        assert -d <= search.fun + 1e-9 + EPA_TOLERANCE
        assert d >= res.min_distance - COAL_EPA  # never deeper than coal
        if {ka, kb} != {SPHERE, CYLINDER}:  # coal pushes a sphere centred inside a cylinder
            assert d == pytest.approx(res.min_distance, abs=COAL_EPA)  # out radially only
    assert checked >= 5


# ------------------------------------------------------------------ on the robot
def _world(xyz, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    T[:3, 3] = xyz
    return T


@pytest.fixture(scope="module")
def scene(humanoid) -> CollisionModel:
    """The paper's robot with its URDF's hands (boxes, cylinders, spheres), an obstacle of
    every shape around the right hand and the shelf board of tasks/reach_under_shelf.toml."""
    hand = humanoid.frame_pose(humanoid.home(), "right_tool")[:3, 3]

    def at(*offset, rpy=(0.0, 0.0, 0.0)):
        return _world(hand + np.asarray(offset), rpy)

    obstacles = [
        Obstacle("board", "box", (0.3, 0.4, 0.03), at(0.0, 0.0, -0.12)),
        Obstacle("post", "cylinder", (0.03, 0.4), at(0.1, 0.15, 0.0, rpy=(0.3, 0, 0))),
        Obstacle("ball", "sphere", (0.05,), at(0.0, 0.15, 0.1)),
        Obstacle("rod", "capsule", (0.02, 0.3), at(0.15, -0.1, 0.05, rpy=(0, 1.2, 0))),
        Obstacle("shelf_board", "box", (0.3, 0.8, 0.03), _world((1.0, -0.5, 0.945))),
    ]
    return CollisionModel(humanoid, obstacles, shapes={"left_hand": "urdf", "right_hand": "urdf"})


def _postures(robot: wb.Robot, n: int, seed: int, near_home: bool = False) -> list[np.ndarray]:
    """Random postures, or postures near home (the right hand among the obstacles)."""
    rng = np.random.default_rng(seed)
    if near_home:
        home = robot.home()
        return [robot.integrate(home, rng.normal(scale=0.15, size=robot.nu), 1.0) for _ in range(n)]
    return [robot.random_configuration(rng, margin=0.1, base_range=0.3) for _ in range(n)]


def test_rows_are_the_derivative_of_the_distance_along_random_velocities(humanoid, scene):
    """``row . u`` against ``(d(q + A u dt) - d(q - A u dt)) / 2 dt`` (dt = 1e-6 s), for the
    six closest pairs within 10 cm of random postures and every obstacle's pair there:
    1e-6 m/s per m/s of ``u`` apart (finite differences), 1e-5 overlapping (EPA's facets on a
    cylinder); every obstacle shape takes part."""
    rng = np.random.default_rng(7)
    obstacles = {o.name for o in scene.obstacles}
    dt, checked, met = 1e-6, 0, set()
    for q in _postures(humanoid, 3, 3) + _postures(humanoid, 6, 3, near_home=True):
        near = scene.distances(humanoid.update(q), 0.1)
        for pair in near[:6] + [p for p in near[6:] if p.b in obstacles]:
            u = rng.normal(size=humanoid.nu)
            u /= np.linalg.norm(u)

            def d(s, name=pair.name, near=pair.distance + 1e-3):
                return next(p.distance for p in scene.distances(s, near) if p.name == name)

            ahead = d(humanoid.update(humanoid.integrate(q, u, dt)))
            rate = (ahead - d(humanoid.update(humanoid.integrate(q, -u, dt)))) / (2 * dt)
            assert pair.row @ u == pytest.approx(rate, abs=1e-6 if pair.distance > 0 else 1e-5)
            checked += 1
            met.add(pair.b if pair.b in obstacles else "self")
    assert checked >= 40 and met == obstacles | {"self"}


def test_the_broad_phase_never_drops_a_pair_within_reach(humanoid, scene):
    """Every pair closer than ``within`` by the exact distance of every pair (no cut-off) is
    found with the cut-off, with the same numbers, for cut-offs from 1 mm to 30 cm."""
    for q in _postures(humanoid, 4, 11):
        state = humanoid.update(q)
        every = {p.name: p for p in scene.distances(state)}
        assert len(every) == len(scene.pairs)
        for within in (0.001, 0.02, 0.05, 0.3):
            near = scene.distances(humanoid.update(q), within)
            assert {p.name for p in near} == {n for n, p in every.items() if p.distance < within}
            for p in near:
                assert p.distance == every[p.name].distance
                np.testing.assert_array_equal(p.row, every[p.name].row)


def test_max_rows_keeps_the_closest_pairs_closest_first_and_counts_the_rest(humanoid, scene):
    """With room for 3 rows the kernel writes the 3 closest pairs, sorted, the rows of those
    pairs, and says how many were within."""
    J, oMf = humanoid.kinematics.views()
    for q in _postures(humanoid, 3, 5):
        every = scene.distances(humanoid.update(q), 0.2)
        J, oMf = humanoid.kinematics.views()
        rows, found = np.empty((3, humanoid.nu)), np.empty((len(scene.pairs), RESULT_WIDTH))
        index = np.empty(len(scene.pairs), dtype=np.int64)
        external = np.empty((0, RESULT_WIDTH))
        n, near = collision_rows(J, oMf, scene.packed, external, 0.2, rows, found, index)
        assert near == len(every) and n == min(3, near)
        assert [p.distance for p in every] == sorted(p.distance for p in every)
        for r in range(n):
            assert scene.pair_name(*scene.pairs[index[r]]) == every[r].name
            assert found[r, 0] == every[r].distance
            np.testing.assert_array_equal(rows[r], every[r].row)
        # nearest_pairs alone, with no room at all
        assert nearest_pairs(oMf, scene.packed, external, 0.2, found[:0], index) == (0, near)


def test_the_shelf_board_pair_at_the_goal_matches_coal(humanoid):
    """The robot (hands as capsules, robot.toml) with tasks/reach_under_shelf.toml's board
    at random postures: every pair's distance is coal's on the same placements (Pinocchio's
    ``computeDistances``): 1e-9 m apart, coal's EPA tolerance overlapping."""
    board = Obstacle("shelf_board", "box", (0.3, 0.8, 0.03), _world((1.0, -0.5, 0.945)))
    model = CollisionModel(humanoid, [board])
    geometry = model.geometry.copy()
    for i, k in model.pairs:
        geometry.addCollisionPair(pin.CollisionPair(i, k))
    data = pin.GeometryData(geometry)
    for request in data.distanceRequests:
        request.gjk_tolerance = 1e-9
    for q in _postures(humanoid, 3, 17):
        state = humanoid.update(q)
        ours = {p.name: p for p in model.distances(state)}
        pin.updateGeometryPlacements(humanoid.model, humanoid.data, geometry, data)
        pin.computeDistances(geometry, data)
        for c, pair in enumerate(geometry.collisionPairs):
            res = data.distanceResults[c]
            p = ours[model.pair_name(pair.first, pair.second)]
            if res.min_distance > 0:
                assert p.distance == pytest.approx(
                    res.min_distance, abs=COAL_GJK * max(1, p.distance)
                )
            else:
                assert p.distance == pytest.approx(res.min_distance, abs=COAL_EPA)
