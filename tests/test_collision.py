"""Collision avoidance: shapes and pairs, distances against coal through Pinocchio, rows
against finite differences (also at the switch-on distance), and a reach through an obstacle
that both backends stop at the safety distance."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.collision import CollisionModel, Obstacle
from wholebody.errors import ConfigError, DimensionError
from wholebody.planning import MinimumJerkTrajectory
from wholebody.testing import jacobian_fd

DT = 0.01


def _pose(xyz, rpy=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    T[:3, 3] = xyz
    return T


@pytest.fixture(scope="module")
def scene(humanoid):
    """The robot with one obstacle of every shape around its right hand."""
    hand = humanoid.frame_pose(humanoid.home(), "right_tool")[:3, 3]

    def at(*offset, rpy=(0.0, 0.0, 0.0)):
        return _pose(hand + np.asarray(offset), rpy)

    obstacles = [
        Obstacle("board", "box", (0.3, 0.4, 0.03), at(0.0, 0.0, -0.12)),
        Obstacle("post", "cylinder", (0.03, 0.4), at(0.1, 0.15, 0.0, rpy=(0.3, 0, 0))),
        Obstacle("ball", "sphere", (0.05,), at(0.0, 0.15, 0.1)),
        Obstacle("rod", "capsule", (0.02, 0.3), at(0.15, -0.1, 0.05, rpy=(0, 1.2, 0))),
    ]
    return CollisionModel(humanoid, obstacles)


def test_pairs_leave_out_adjacent_links_and_contacts_at_home_and_say_why(humanoid, scene):
    reasons = set(scene.excluded.values())
    assert "adjacent links" in reasons and "same joint" in reasons
    assert any("at the home posture" in r for r in reasons)
    names = {scene.pair_name(i, k) for i, k in scene.pairs}
    assert "right_wrist_0|right_hand_0_capsule" not in names  # adjacent
    assert "right_elbow_0|right_forearm_0" not in names
    assert "right_hand_0_capsule|ball" in names and "chest_0|left_hand_0_capsule" in names
    state = humanoid.update(humanoid.home())
    assert min(p.distance for p in scene.distances(state)) >= 0.01  # none in contact at home
    assert "pairs checked" in scene.summary()


def test_distances_match_pinocchio_and_coal(humanoid, scene, rng):
    """Every checked pair's distance equals Pinocchio's computeDistance on the same model."""
    data = pin.GeometryData(scene.geometry)
    geometry = scene.geometry.copy()
    for i, k in scene.pairs:
        geometry.addCollisionPair(pin.CollisionPair(i, k))
    data = pin.GeometryData(geometry)
    for _ in range(3):
        q = humanoid.random_configuration(rng, margin=0.1, base_range=0.3)
        state = humanoid.update(q)
        ours = {p.name: p.distance for p in scene.distances(state)}
        pin.updateGeometryPlacements(humanoid.model, humanoid.data, geometry, data)
        pin.computeDistances(geometry, data)
        for c, pair in enumerate(geometry.collisionPairs):
            name = scene.pair_name(pair.first, pair.second)
            assert ours[name] == pytest.approx(data.distanceResults[c].min_distance, abs=1e-5)


def test_rows_are_the_distances_derivative(humanoid, scene, rng):
    """``n^T (J_b - J_a)`` against central differences of the distance, for the pairs within
    15 cm of random postures (1e-4: GJK's witness points on two curved shapes)."""
    checked = 0
    for _ in range(4):
        q = humanoid.random_configuration(rng, margin=0.1, base_range=0.3)
        for pair in scene.distances(humanoid.update(q), 0.15)[:8]:

            def distance(s, n=pair.name):
                return np.array([next(p.distance for p in scene.distances(s, 0.2) if p.name == n)])

            fd = jacobian_fd(humanoid, q, distance, 1e-5)
            np.testing.assert_allclose(pair.row, fd[0], atol=1e-4)
            checked += 1
    assert checked >= 10


def test_the_row_appears_at_the_influence_distance_with_the_full_approach_speed(humanoid):
    """A ball placed so that the hand is just inside d_i: one row, its bound -xi, and the row
    is the distance's derivative there."""
    q = humanoid.home()
    state = humanoid.update(q)
    probe = CollisionModel(humanoid, [Obstacle("ball", "sphere", (0.05,), _pose((3, 0, 0)))])
    hand = next(p for p in probe.distances(state) if p.name == "right_hand_0_capsule|ball")
    centre = hand.point_a + (0.05 - 1e-6 + 0.05) * hand.normal  # the hand just inside d_i
    model = CollisionModel(humanoid, [Obstacle("ball", "sphere", (0.05,), _pose(centre))])
    task = wb.CollisionAvoidance(humanoid, model, safety=0.01, influence=0.05, speed=0.5)
    rows = task.compute(humanoid.update(q), DT)
    r = task.row_names().index("right_hand_0_capsule|ball")
    assert task.pairs[r].distance == pytest.approx(0.05 - 1e-6, abs=1e-7)
    assert rows.lower[r] == pytest.approx(-0.5, abs=1e-4)
    assert np.isinf(rows.lower[len(task.pairs) :]).all()  # the unused rows are inactive
    fd = jacobian_fd(
        humanoid,
        q,
        lambda s: np.array(
            [next(p.distance for p in model.distances(s, 0.1) if p.name == task.pairs[r].name)]
        ),
        1e-5,
    )
    np.testing.assert_allclose(rows.C[r], fd[0], atol=1e-6)


def _reach_past_a_ball(humanoid, solver, constrained):
    """The right hand moved 30 cm left in 2 s past a ball 7 cm above its path: the smallest
    distance of any pair over 3 s, and the solver's messages."""
    q = humanoid.home()
    start = humanoid.frame_pose(q, "right_tool")
    goal = start.copy()
    goal[:3, 3] += (0.0, 0.3, 0.0)
    ball = Obstacle("ball", "sphere", (0.05,), _pose(start[:3, 3] + (0.0, 0.15, 0.07)))
    collision = wb.CollisionAvoidance(humanoid, obstacles=[ball])
    hand = wb.FrameTask(humanoid, "right_tool", kp=10.0, orientation=False)
    levels = [[collision], [hand]] if constrained else [[hand]]
    stack = wb.Stack(
        humanoid, levels, [wb.JointPositionLimits(humanoid), wb.VelocityLimits(humanoid)]
    )
    reference = MinimumJerkTrajectory(start, goal, 2.0)
    closest, messages = np.inf, set()
    for k in range(300):
        hand.set_target(reference.sample(min(k * DT, 2.0)).pose)
        state = humanoid.update(q)
        closest = min([closest, *(p.distance for p in collision.model.distances(state, 0.05))])
        result = solver.solve(stack, state, DT)
        messages.add(result.message)
        q = humanoid.integrate(q, result.u, DT)
    state = humanoid.update(q)
    return closest, messages, collision


@pytest.mark.slow
@pytest.mark.parametrize("backend", [wb.ProjectionSolver, wb.HierarchicalQPSolver])
def test_a_reach_past_an_obstacle_keeps_the_safety_distance_on_every_step(humanoid, backend):
    free, _, _ = _reach_past_a_ball(humanoid, backend(), constrained=False)
    assert free < 0.0  # the unconstrained hand goes through the ball
    closest, messages, collision = _reach_past_a_ball(humanoid, backend(), constrained=True)
    assert closest >= collision.safety
    if backend is wb.ProjectionSolver:  # the held row and the task it limited are named
        assert any(
            re.search(
                r"held inequality rows: collision\[\d+\] right_hand_\d_capsule\|ball"
                r".*limited: right_tool",
                m,
            )
            for m in messages
        )


def test_every_link_can_be_one_capsule_or_keep_its_own_shapes(humanoid):
    """``"*"`` simplifies every link not named; ``"urdf"`` keeps a link's own shapes."""
    model = CollisionModel(humanoid, shapes={"*": "capsule", "chest": "urdf"})
    names = [o.name for o in model.geometry.geometryObjects]
    assert {"chest_0", "chest_1"} <= set(names)
    others = [n for n in names if not n.startswith("chest_")]
    assert others and all(n.endswith("_capsule") for n in others)
    # a bounding capsule holds its link's shapes: no closer to anything than they were
    state = humanoid.update(humanoid.home())

    def against_chest(m):  # (chest shape, other link) -> distance: the chest keeps its shapes
        out: dict[tuple[str, str], float] = {}
        for p in m.distances(state):
            a, b = p.name.split("|")
            if a.startswith("chest_") != b.startswith("chest_"):
                key = (a, p.b) if a.startswith("chest_") else (b, p.a)
                out[key] = min(p.distance, out.get(key, np.inf))
        return out

    plain, capsules = against_chest(CollisionModel(humanoid)), against_chest(model)
    common = set(plain) & set(capsules)
    assert len(common) > 10
    assert all(capsules[k] <= plain[k] + 1e-9 for k in common)


def test_bad_settings_are_named(humanoid, tmp_path):
    with pytest.raises(DimensionError, match="safety < influence"):
        wb.CollisionAvoidance(humanoid, safety=0.05, influence=0.05)
    with pytest.raises(DimensionError, match="a sphere needs 1 sizes"):
        CollisionModel(humanoid, [Obstacle("b", "sphere", (0.1, 0.2))])
    with pytest.raises(DimensionError, match="shape must be one of"):
        CollisionModel(humanoid, [Obstacle("b", "cone", (0.1,))])
    with pytest.raises(DimensionError, match="unknown link or shape 'elbow'"):
        CollisionModel(humanoid, exclude=[("elbow", "chest")])
    task = wb.CollisionAvoidance(humanoid, speed=5.0)
    with pytest.raises(DimensionError, match="a step could cross the safety distance"):
        task.compute(humanoid.update(humanoid.home()), DT)
    toml = (wb.load_robot("mobile_humanoid").config.path).read_text()
    bad = tmp_path / "robot.toml"
    bad.write_text(
        toml.replace('right_hand = "capsule"', 'right_hand = "cone"').replace(
            'urdf = "robot.urdf"', f'urdf = "{humanoid.config.urdf}"'
        )
    )
    with pytest.raises(ConfigError, match=r"collision\.shapes"):
        wb.load_robot(bad)


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["projection", "hqp"])
def test_the_shelf_scenario_stops_the_hand_at_the_safety_distance(backend):
    """tasks/reach_under_shelf.toml: without the constraint the hand's capsule goes into the
    board; with it every pair stays at or above 1 cm on every step, the pair that held the
    hand back is named, and the joint limits hold."""
    import dataclasses

    from wholebody.resources import tasks_dir
    from wholebody.scenarios import load_scenario, run_scenario

    spec = load_scenario(tasks_dir() / "reach_under_shelf.toml")
    off = dataclasses.replace(spec, collision=dataclasses.replace(spec.collision, enforce=False))
    free = run_scenario(off, backend=backend).metrics
    assert free["min_collision_distance_m"] < 0.0
    assert free["min_collision_pair"] == "right_hand_1_capsule|shelf_board"
    m = run_scenario(spec, backend=backend).metrics
    assert m["min_collision_distance_m"] >= 0.01 - 1e-5  # to the first-order step's error
    assert m["limit_violations"] == 0
    assert "pairs checked" in m["collision_pairs"] and "adjacent links" in m["collision_pairs"]
    assert [(e["pair"], e["task"]) for e in m["collision_limited"]] == [
        ("right_hand_1_capsule|shelf_board", "right")
    ]


def test_obstacles_near_the_hand_at_home_are_checked_and_overlaps_measured(humanoid):
    """An obstacle 9 mm from the hand at home keeps its pair (only self pairs are left out
    for contact at home); a ball overlapping the hand's capsule by 1 cm: distance -1 cm,
    the normal from the capsule's axis to the ball's centre, the row the derivative."""
    q = humanoid.home()
    state = humanoid.update(q)
    probe = CollisionModel(humanoid, [Obstacle("ball", "sphere", (0.05,), _pose((3, 0, 0)))])
    hand = next(p for p in probe.distances(state) if p.name == "right_hand_0_capsule|ball")
    near = hand.point_a + (0.009 + 0.05) * hand.normal
    model = CollisionModel(humanoid, [Obstacle("ball", "sphere", (0.05,), _pose(near))])
    assert any(p.name == "right_hand_0_capsule|ball" for p in model.distances(state, 0.02))
    inside = hand.point_a + (0.05 - 0.01) * hand.normal
    model = CollisionModel(humanoid, [Obstacle("ball", "sphere", (0.05,), _pose(inside))])
    pair = next(p for p in model.distances(state) if p.name == "right_hand_0_capsule|ball")
    assert pair.distance == pytest.approx(-0.01, abs=1e-6)
    np.testing.assert_allclose(pair.normal, hand.normal, atol=1e-6)
    fd = jacobian_fd(
        humanoid,
        q,
        lambda s: np.array(
            [next(p.distance for p in model.distances(s, 0.1) if p.name == pair.name)]
        ),
        1e-5,
    )
    np.testing.assert_allclose(pair.row, fd[0], atol=1e-6)


def test_poses_names_and_speeds_are_checked(humanoid, tmp_path):
    scaled = np.diag([2.0, 1.0, 1.0, 1.0])
    with pytest.raises(DimensionError, match="rigid 4x4 transform"):
        CollisionModel(humanoid, [Obstacle("b", "sphere", (0.1,), scaled)])
    with pytest.raises(DimensionError, match="not a link's or a shape's"):
        CollisionModel(humanoid, [Obstacle("chest", "sphere", (0.1,))])
    from wholebody.resources import tasks_dir
    from wholebody.scenarios import load_scenario

    text = (tasks_dir() / "reach_under_shelf.toml").read_text()
    bad = tmp_path / "fast.toml"
    bad.write_text(text.replace("influence = 0.05", "influence = 0.05\nspeed = 10.0"))
    with pytest.raises(ConfigError, match="a step could cross the safety distance"):
        load_scenario(bad)


def test_a_real_robot_with_meshes_builds_and_gives_finite_rows():
    """TALOS's URDF meshes: the model builds (meshes in contact at home are left out, not an
    error) and every row within 5 cm at home is finite; with every shape a capsule too."""
    from wholebody.robot.urdf import example_robot_data_share

    if example_robot_data_share() is None:
        pytest.skip("example-robot-data is not installed (pip install '.[robots]')")
    talos = wb.load_robot("talos_upper")
    state = talos.update(talos.home())
    for shapes in (None, {"*": "capsule"}):
        model = CollisionModel(talos, shapes=shapes)
        near = model.distances(state, 0.05)
        assert near and all(np.all(np.isfinite(p.row)) for p in near)
        assert any("at the home posture" in r for r in model.excluded.values()) or shapes


def test_a_carried_object_moves_with_its_hand_and_its_grasp_is_not_a_collision(humanoid, rng):
    """A box held at the right tool, in the hand: the pairs it touches at the grasp are left
    out, it keeps a fixed pose relative to the hand, and its rows are the derivative of its
    distances (it moves with the arm)."""
    q0 = humanoid.home()
    box = Obstacle("parcel", "box", (0.1, 0.2, 0.05), _pose((0.03, 0.0, 0.0)))  # in the hand
    wall = Obstacle("wall", "box", (0.05, 2.0, 2.0), _pose((1.6, 0.0, 1.0)))
    model = CollisionModel(humanoid, [wall], attached=[("right_tool", box)], start=q0)
    assert model.excluded[("right_hand_0_capsule", "parcel")] == "same joint"  # the grasp
    assert "right_forearm_0|parcel" in {model.pair_name(i, k) for i, k in model.pairs}
    for _ in range(3):
        q = humanoid.random_configuration(rng, margin=0.2, base_range=0.3)
        state = humanoid.update(q)
        tool = state.pose(humanoid.frame("right_tool"))
        k = [o.name for o in model.geometry.geometryObjects].index("parcel")
        pin.updateGeometryPlacements(humanoid.model, humanoid.data, model.geometry, model.data)
        np.testing.assert_allclose(model.data.oMg[k].homogeneous, tool @ box.pose, atol=1e-12)
        pair = next(p for p in model.distances(state) if p.name == "parcel|wall")
        fd = jacobian_fd(
            humanoid,
            q,
            lambda s: np.array(
                [next(p.distance for p in model.distances(s) if p.name == "parcel|wall")]
            ),
            1e-5,
        )
        np.testing.assert_allclose(pair.row, fd[0], atol=1e-6)


@pytest.mark.slow
def test_the_carry_keeps_the_carried_panel_as_a_collision_shape(tmp_path):
    """coordinated_carry with [collision]: during the carry the panel is checked against
    the shelf (its pair is in the metrics' closest approach) and the run holds its limits."""
    import shutil

    from wholebody.resources import tasks_dir
    from wholebody.scenarios import load_scenario, run_scenario

    shutil.copytree(tasks_dir(), tmp_path / "tasks")
    path = tmp_path / "tasks" / "coordinated_carry.toml"
    text = path.read_text().replace(
        "[[phases]]", '[collision]\nobstacles = ["shelf_board"]\n\n[[phases]]', 1
    )
    path.write_text(text)
    m = run_scenario(load_scenario(path), backend="hqp").metrics
    assert m["min_collision_pair"] == "panel|shelf_board"  # it rests on the board at the grasp
    assert m["min_collision_distance_m"] > -1e-6 and m["limit_violations"] == 0
