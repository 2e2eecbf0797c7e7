"""The actuated velocity space ``u``: which velocities a controller commands, and the map
from them to the model's velocities.

Tasks and solvers work in ``u`` (size ``nu``): first the base actuators (wheel speeds in
rad/s, or the twist of a directly actuated planar base), then one speed per remaining 1-DOF
joint in model order. The model velocity is ``v = A u`` with the constant actuation matrix
``A`` (nv x nu):

* the root joint's rows (three of a planar root, six of a free flyer) are the base model's
  ``B`` (twist = ``B u_base``, :mod:`wholebody.robot.base`), with the URDF's wheel axes
  (:mod:`wholebody.robot.wheels`);
* a joint the base holds (a swerve module's steering and drive) has a zero row: no entry of
  ``u`` moves it;
* every other joint's row is a unit row in its own column;
* a mimic joint ``q_f = m q_leader + o`` is no entry of ``u``: its row is ``m`` in the
  leader's column, and its position and velocity limits narrow the leader's.

Every Jacobian a robot returns is ``J_model A``, so a wheel's limits are hard bounds on ``u``
like any joint's, and a mimic joint moves with its leader in every task.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wholebody.errors import ModelError
from wholebody.robot._names import suggest
from wholebody.robot.base import ANGULAR_ACTUATORS, BaseModel
from wholebody.robot.config import RobotConfig
from wholebody.robot.urdf import Mimic, UrdfInfo
from wholebody.robot.wheels import wheel_geometry

__all__ = ["BASE", "CONTINUOUS", "SCALAR", "Actuation", "build_actuation"]

SCALAR, CONTINUOUS, BASE = 0, 1, 2
"""What holds an entry of ``u``'s position in ``q``: one scalar (revolute, prismatic), a
(cos, sin) pair (a continuous joint, a wheel), or the root joint's pose (a virtual actuator of
a planar or floating base)."""


@dataclass(frozen=True)
class Actuation:
    """The actuated velocity space of a model (module docstring); arrays read-only.

    Attributes
    ----------
    joints
        The name of each entry of ``u`` (base actuators first).
    matrix
        ``A`` (nv x nu).
    lower, upper
        Position limits per entry of ``u`` (rad, m; ``-inf``, ``inf`` where there is none).
    velocity
        Velocity limits per entry of ``u`` (rad/s, m/s; ``inf`` where there is none).
    kinds
        Per entry of ``u``: :data:`SCALAR`, :data:`CONTINUOUS` or :data:`BASE`.
    q_index
        Per entry of ``u``, the index of its position (or its cos) in ``q``.
    joint_ids
        The model's joints below the root, by name.
    followers
        The mimic joints of the model (not locked), by name.
    mimic
        ``(q index, leader's q index, multiplier, offset)`` per mimic joint.
    base
        The base model, with the URDF's wheel axes and axle.
    """

    joints: tuple[str, ...]
    matrix: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    kinds: np.ndarray
    q_index: np.ndarray
    joint_ids: dict[str, int]
    followers: dict[str, Mimic]
    mimic: list[tuple[int, int, float, float]]
    base: BaseModel


def build_actuation(
    config: RobotConfig,
    model: pin.Model,
    urdf: UrdfInfo,
    base: BaseModel,
    locked: Mapping[str, float] | None = None,
) -> Actuation:
    """The actuated velocity space of ``model`` (loaded from ``config``'s URDF) with ``base``
    at its root: :class:`ModelError` for a joint wholebody cannot actuate (more than one
    DOF, or a range of zero), a ``config`` error for a wheel that is not a joint (or that
    ``locked``, the joints ``[locked]`` removed, holds)."""
    joint_ids = _joint_ids(config, model, base, locked or {})
    if base.wheel_joints:
        base = wheel_geometry(model, base, joint_ids, config)
    # a mimic joint (not locked) is no velocity of u: its leader's moves it (below)
    followers = {f: m for f, m in urdf.mimic.items() if f in joint_ids}
    moved = set(base.wheel_joints) | set(followers) | set(base.held)
    names = list(base.actuators) + [n for n in joint_ids if n not in moved]
    nu = len(names)
    A = np.zeros((model.nv, nu))
    lower = np.full(nu, -np.inf)
    upper = np.full(nu, np.inf)
    vmax = np.full(nu, np.inf)
    kinds = np.zeros(nu, dtype=int)
    qidx = np.zeros(nu, dtype=int)
    nb = len(base.actuators)
    if base.mobile:
        A[0 : base.root_nv, 0:nb] = base.matrix
    for k, name in enumerate(names):
        if name not in joint_ids:  # virtual base actuator
            kinds[k] = BASE
            qidx[k] = k
            b = config.base
            vmax[k] = b.max_angular_velocity if name in ANGULAR_ACTUATORS else b.max_linear_velocity
            continue
        j = joint_ids[name]
        iv, iq = model.joints[j].idx_v, model.joints[j].idx_q
        A[iv, k] = 1.0
        qidx[k] = iq
        vmax[k] = model.velocityLimit[iv]
        if model.joints[j].nq == 2:
            kinds[k] = CONTINUOUS
        else:
            lower[k] = model.lowerPositionLimit[iq]
            upper[k] = model.upperPositionLimit[iq]
    own = lower.copy(), upper.copy()
    mimic = _couple_mimics(config, model, joint_ids, followers, names, A, lower, upper, vmax)
    lower[~np.isfinite(lower) | (lower < -1e300)] = -np.inf
    upper[~np.isfinite(upper) | (upper > 1e300)] = np.inf
    _check_movable(
        config, names, lower, upper, kinds, own, _mimic_ranges(model, joint_ids, followers)
    )
    vmax[vmax <= 0] = np.inf  # URDF velocity 0 means "not given"
    for arr in (A, lower, upper, vmax, kinds, qidx):
        arr.setflags(write=False)
    return Actuation(
        tuple(names), A, lower, upper, vmax, kinds, qidx, joint_ids, followers, mimic, base
    )


def _joint_ids(
    config: RobotConfig, model: pin.Model, base: BaseModel, locked: Mapping[str, float]
) -> dict[str, int]:
    """The model's joints below the root by name, each checked to have one DOF, and the
    wheels checked to be among them (not ``locked``)."""
    first = 2 if base.mobile else 1  # joint 0 = universe, 1 = the root joint if mobile
    joint_ids = {model.names[j]: j for j in range(first, model.njoints)}
    for name, j in joint_ids.items():
        if model.joints[j].nv != 1:
            raise ModelError(
                f"{config.urdf}: joint {name!r} has {model.joints[j].nv} DOF; "
                "wholebody supports 1-DOF joints (revolute, continuous, prismatic) "
                "below the root"
            )
    for w in base.wheel_joints:
        if w in locked:
            raise config.error(
                "base.wheels",
                f"wheel joint {w!r} is locked ([locked] holds it "
                f"at {locked[w]:g}): a wheel of the base must turn; take it out "
                "of [locked] (or out of the pattern or group that matches it)",
            )
        if w not in joint_ids:
            raise config.error(
                "base.wheels",
                f"wheel joint {w!r} is not a joint of {config.urdf.name}" + suggest(w, joint_ids),
            )
    for k, m in enumerate(config.base.modules):
        for j in (m.steering, m.drive):
            if j not in joint_ids:
                raise config.error(
                    f"base.modules[{k}]",
                    f"{j!r} is not a moving joint of {config.urdf.name}" + suggest(j, joint_ids),
                )
    return joint_ids


def _couple_mimics(
    config: RobotConfig,
    model: pin.Model,
    joint_ids: Mapping[str, int],
    followers: Mapping[str, Mimic],
    names: Sequence[str],
    A: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    vmax: np.ndarray,
) -> list[tuple[int, int, float, float]]:
    """Each mimic joint moves with its leader: its row of ``A`` is ``multiplier`` in the
    leader's column, and its position and velocity limits narrow the leader's (in the
    leader's coordinate). Returns ``(q index, leader's q index, multiplier, offset)``."""
    index = {n: k for k, n in enumerate(names)}
    out = []
    for name, m in followers.items():
        jf, jl = model.joints[joint_ids[name]], model.joints[joint_ids[m.leader]]
        if jf.nq != 1 or jl.nq != 1:
            raise ModelError(
                f"{config.urdf}: mimic joint {name!r}: wholebody "
                "couples revolute and prismatic joints only"
            )
        k = index[m.leader]
        A[jf.idx_v, k] = m.multiplier
        lo, hi = model.lowerPositionLimit[jf.idx_q], model.upperPositionLimit[jf.idx_q]
        if abs(lo) < 1e300 and abs(hi) < 1e300:
            a, b = sorted(((lo - m.offset) / m.multiplier, (hi - m.offset) / m.multiplier))
            lower[k], upper[k] = max(lower[k], a), min(upper[k], b)
        if model.velocityLimit[jf.idx_v] > 0:
            vmax[k] = min(vmax[k], model.velocityLimit[jf.idx_v] / abs(m.multiplier))
        out.append((jf.idx_q, jl.idx_q, m.multiplier, m.offset))
    return out


def _mimic_ranges(
    model: pin.Model, joint_ids: Mapping[str, int], followers: Mapping[str, Mimic]
) -> dict[str, list[str]]:
    """Per leader, each mimic joint's own limits and what they allow the leader, in words:
    ``"'f' (q_f = -1 q_l + 0; limits [0, 0.548] in the URDF, so [-0.548, 0] for 'l')"``."""
    out: dict[str, list[str]] = {}
    for name, m in followers.items():
        jf = model.joints[joint_ids[name]]
        lo, hi = model.lowerPositionLimit[jf.idx_q], model.upperPositionLimit[jf.idx_q]
        if jf.nq != 1 or not (abs(lo) < 1e300 and abs(hi) < 1e300):
            continue
        a, b = sorted(((lo - m.offset) / m.multiplier, (hi - m.offset) / m.multiplier))
        out.setdefault(m.leader, []).append(
            f"{name!r} (q = {m.multiplier:g} q_{m.leader} + {m.offset:g}; limits [{lo:g}, "
            f"{hi:g}], so [{a + 0.0:g}, {b + 0.0:g}] for {m.leader!r})"  # -0 printed as 0
        )
    return out


def _check_movable(
    config: RobotConfig,
    names: Sequence[str],
    lower: np.ndarray,
    upper: np.ndarray,
    kinds: np.ndarray,
    own: tuple[np.ndarray, np.ndarray],
    mimics: Mapping[str, list[str]],
) -> None:
    """A :class:`ModelError` for a scalar joint whose range is empty or a point: its own
    (``own``: the URDF's), or once its mimic joints narrowed it (``mimics``: their ranges
    in words, by leader)."""
    for k in np.flatnonzero(~(lower < upper) & (kinds == SCALAR)).tolist():
        name, lo, hi = names[k], own[0][k], own[1][k]
        if lo < hi and name in mimics:
            raise ModelError(
                f"{config.urdf}: joint {name!r} cannot move: its limits [{lo:g}, {hi:g}] and "
                f"those of its mimic joints {'; '.join(mimics[name])} leave "
                f"[{lower[k] + 0.0:g}, {upper[k] + 0.0:g}]; lock {name!r} in [locked] of "
                "robot.toml (its mimic joints are locked with it), or give the mimic joint "
                "the limits it has in [joints]"
            )
        raise ModelError(
            f"{config.urdf}: joint {name!r} cannot move: its limits are "
            f"[{lower[k]:g}, {upper[k]:g}] (a URDF <limit> without lower and upper means "
            f"0 and 0); in robot.toml, give it its range ([joints.{name}] lower = ..., "
            f'upper = ...) or, if it turns endlessly like a wheel, type = "continuous"; '
            "or lock it ([locked]: a fixed joint)"
        )
