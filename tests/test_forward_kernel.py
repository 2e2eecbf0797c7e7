"""Forward kinematics, joint Jacobians and the integration of ``q`` in kernels
(:mod:`wholebody.kernels.forward`) against Pinocchio: on every shipped robot, on free-flyer
models of the bundled URDFs and on a URDF with every joint type the kernels move, to 1e-12
(absolute: translations in m, rotations and Jacobian entries of order 1); and called from a
``prange`` loop, as a batched solve will."""

from __future__ import annotations

import numba
import numpy as np
import pinocchio as pin
import pytest

import wholebody
from wholebody.errors import ModelError
from wholebody.kernels.forward import forward_kinematics, integrate, model_velocity
from wholebody.kernels.kinematics import frame_kinematics
from wholebody.robot import robot_catalogue
from wholebody.robot.compiled import pack_model
from wholebody.robot.parts import Frame

TOL = 1e-12  # the kernels follow Pinocchio's formulas: they differ by rounding only

ROBOTS = [
    pytest.param(name, marks=pytest.mark.skipif(not ok, reason=f"{name}'s package is missing"))
    for name, _, ok in robot_catalogue()
]


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request) -> wholebody.Robot:
    return wholebody.load_robot(request.param)


def _outputs(model: pin.Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """oMi, oMf and J in the layouts of RobotKinematics.views() (J Fortran-ordered)."""
    oMi = np.full((model.njoints, 12), np.nan)
    oMf = np.full((model.nframes, 12), np.nan)
    J = np.full((6, model.nv), np.nan, order="F")
    return oMi, oMf, J


def _placements(placements: list[pin.SE3]) -> np.ndarray:
    return np.array(
        [np.concatenate((M.rotation.ravel(order="F"), M.translation)) for M in placements]
    )


def _check_forward(model: pin.Model, q: np.ndarray, tables: tuple | None = None) -> None:
    """The kernel's oMi, oMf and J at q against Pinocchio's data (``tables``: the packed
    model, by default packed here)."""
    model_i, model_f = tables or pack_model(model)
    oMi, oMf, J = _outputs(model)
    forward_kinematics(model_i, model_f, q, oMi, oMf, J)
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    np.testing.assert_allclose(oMi, _placements(data.oMi), rtol=0, atol=TOL)
    np.testing.assert_allclose(oMf, _placements(data.oMf), rtol=0, atol=TOL)
    np.testing.assert_allclose(J, data.J, rtol=0, atol=TOL)


def _check_integrate(model: pin.Model, q: np.ndarray, v: np.ndarray, dt: float) -> None:
    """The kernel's integrate, out of place and in place, against pin.integrate(q, v dt)."""
    model_i, _ = pack_model(model)
    expected = pin.integrate(model, q, v * dt)
    out = np.full(model.nq, np.nan)
    integrate(model_i, q, v, dt, out)
    np.testing.assert_allclose(out, expected, rtol=0, atol=TOL)
    same = q.copy()
    integrate(model_i, same, v, dt, same)
    np.testing.assert_array_equal(same, out)


def _random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    """A configuration of any model of the kernels' joint types: angles and displacements in
    [-3, 3], (cos, sin) pairs at random angles, a free flyer's quaternion uniform."""
    q = pin.neutral(model)
    for jm in list(model.joints)[1:]:
        i, kind = jm.idx_q, jm.shortname()
        a = rng.uniform(-np.pi, np.pi)
        if kind == "JointModelFreeFlyer":
            quat = rng.normal(size=4)
            q[i : i + 7] = *rng.uniform(-2, 2, 3), *quat / np.linalg.norm(quat)
        elif kind == "JointModelPlanar":
            q[i : i + 4] = *rng.uniform(-2, 2, 2), np.cos(a), np.sin(a)
        elif jm.nq == 2:
            q[i : i + 2] = np.cos(a), np.sin(a)
        else:
            q[i] = rng.uniform(-3, 3)
    return q


# ------------------------------------------------------------------ shipped robots
def test_placements_and_jacobians_are_pinocchios_on_every_robot(robot, rng):
    tables = robot.kinematics.model_tables()
    assert robot.kinematics.model_tables() is tables  # packed once
    assert not any(t.flags.writeable for t in tables)
    for _ in range(20):
        _check_forward(robot.model, robot.random_configuration(rng), tables)


def test_integrate_is_pinocchios_on_every_robot(robot, rng):
    kin = robot.kinematics
    model_i, _ = kin.model_tables()
    v = np.empty(robot.nv)
    for _ in range(20):
        q = robot.random_configuration(rng)
        u, dt = rng.normal(size=robot.nu), rng.uniform(0.0, 0.5)
        model_velocity(kin.act_k, kin.act_j, kin.act_a, u, v)
        np.testing.assert_allclose(v, robot.actuation @ u, rtol=0, atol=TOL)
        out = np.empty(robot.nq)
        integrate(model_i, q, v, dt, out)
        np.testing.assert_allclose(out, robot.integrate(q, u, dt), rtol=0, atol=TOL)


def test_the_frame_kernels_read_these_outputs_as_pinocchios(humanoid, rng):
    """kinematics.frame_kinematics gives the same frame Jacobians from the kernel's outputs
    as from the views of Pinocchio's data."""
    model, kin = humanoid.model, humanoid.kinematics
    frames = [Frame(f.name, i, int(f.parentJoint)) for i, f in enumerate(model.frames)]
    ids, support = np.arange(len(frames)), kin.support(frames)
    oMi, oMf, J = _outputs(model)
    results = []
    q = humanoid.random_configuration(rng)
    humanoid.update(q)
    forward_kinematics(*kin.model_tables(), q, oMi, oMf, J)
    for Jm, oMfm in (kin.views(), (J, oMf)):
        F = len(frames)
        out = np.empty((F, 6, humanoid.nu)), np.empty((F, 3)), np.empty((F, 3, 3))
        frame_kinematics(Jm, oMfm, ids, support, kin.act_k, kin.act_j, kin.act_a, *out)
        results.append(out)
    for mine, theirs in zip(*results, strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=0, atol=TOL)


# ------------------------------------------------------------------ floating bases, every type
@pytest.mark.parametrize("name", ["mobile_humanoid", "dual_arm_torso"])
def test_a_free_flyer_model_of_a_bundled_urdf(name, rng):
    urdf = wholebody.load_robot(name).config.urdf
    model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    assert model.joints[1].shortname() == "JointModelFreeFlyer"
    for scale in (0.0, 1e-9, 1e-3, 1.0, 5.0):  # both sides of exp6's and exp3's expansions
        q = _random_q(model, rng)
        _check_forward(model, q)
        _check_integrate(model, q, scale * rng.normal(size=model.nv), rng.uniform(0.1, 1.0))


EVERY_TYPE = {
    *(f"JointModel{k}{a}" for k in ("R", "RUB", "P") for a in "XYZ"),
    "JointModelRevoluteUnaligned",
    "JointModelRevoluteUnboundedUnaligned",
    "JointModelPrismaticUnaligned",
}


def _every_type_urdf(rng: np.random.Generator) -> str:
    """A URDF tree with every joint type of the kernels: revolute, continuous and prismatic
    joints about x, y, z and unaligned axes, each at a random origin below a random earlier
    link, and a fixed joint (a frame)."""
    unaligned = rng.normal(size=3)
    axes = [(1, 0, 0), (0, 1, 0), (0, 0, 1), tuple(unaligned / np.linalg.norm(unaligned))]
    joints = [(t, a) for t in ("revolute", "continuous", "prismatic") for a in axes]
    joints.append(("fixed", axes[0]))
    links = ['<link name="l0"/>']
    for n, (kind, axis) in enumerate(joints, start=1):
        xyz = " ".join(map(str, rng.uniform(-0.5, 0.5, 3)))
        rpy = " ".join(map(str, rng.uniform(-np.pi, np.pi, 3)))
        parent = f"l{rng.integers(0, n)}"
        links.append(
            f'<link name="l{n}"/><joint name="j{n}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="l{n}"/><origin xyz="{xyz}" rpy="{rpy}"/>'
            f'<axis xyz="{" ".join(map(str, axis))}"/>'
            '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
    return f'<robot name="every_type">{"".join(links)}</robot>'


@pytest.mark.parametrize("root", ["free_flyer", "planar", "fixed"])
def test_every_joint_type_against_pinocchio(root, rng):
    roots = {"free_flyer": pin.JointModelFreeFlyer(), "planar": pin.JointModelPlanar()}
    for _ in range(5):
        xml = _every_type_urdf(rng)
        model = pin.buildModelFromXML(xml, *([roots[root]] if root in roots else []))
        assert {j.shortname() for j in model.joints} >= EVERY_TYPE
        for scale in (0.0, 1e-9, 1e-3, 1.0, 5.0):
            q = _random_q(model, rng)
            _check_forward(model, q)
            _check_integrate(model, q, scale * rng.normal(size=model.nv), rng.uniform(0.1, 1.0))


def test_a_joint_of_another_type_is_named():
    model = pin.Model()
    model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "shoulder_ball")
    with pytest.raises(ModelError, match="'shoulder_ball' is a JointModelSpherical"):
        pack_model(model)


# ------------------------------------------------------------------ many states at once
@numba.njit(parallel=True)
def _batch(
    model_i: np.ndarray,
    model_f: np.ndarray,
    Q: np.ndarray,
    V: np.ndarray,
    dt: float,
    oMi: np.ndarray,
    oMf: np.ndarray,
    Jt: np.ndarray,
    Qnext: np.ndarray,
) -> None:
    """Every state n of the batch at once: its kinematics and its next configuration (J of
    state n is Jt[n].T, the Fortran-ordered 6 x nv of data.J)."""
    for n in numba.prange(Q.shape[0]):
        forward_kinematics(model_i, model_f, Q[n], oMi[n], oMf[n], Jt[n].T)
        integrate(model_i, Q[n], V[n], dt, Qnext[n])


def test_a_prange_loop_over_many_states_matches_one_by_one(humanoid, rng):
    model = humanoid.model
    model_i, model_f = humanoid.kinematics.model_tables()
    N = 64
    Q = np.array([humanoid.random_configuration(rng) for _ in range(N)])
    V = rng.normal(size=(N, model.nv))
    oMi, oMf = np.empty((N, model.njoints, 12)), np.empty((N, model.nframes, 12))
    Jt, Qnext = np.empty((N, model.nv, 6)), np.empty((N, model.nq))
    _batch(model_i, model_f, Q, V, 0.01, oMi, oMf, Jt, Qnext)
    one, q_next = _outputs(model), np.empty(model.nq)
    for n in range(N):
        forward_kinematics(model_i, model_f, Q[n], *one)
        integrate(model_i, Q[n], V[n], 0.01, q_next)
        np.testing.assert_array_equal(oMi[n], one[0])
        np.testing.assert_array_equal(oMf[n], one[1])
        np.testing.assert_array_equal(Jt[n].T, one[2])
        np.testing.assert_array_equal(Qnext[n], q_next)
