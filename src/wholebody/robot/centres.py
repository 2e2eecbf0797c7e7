"""Joint centres of an arm: where its shoulder, elbow and wrist frames must be, and frames to
put there when they are not.

The arm geometry (arm angle, posture mapping, the arm energy's lengths) takes the shoulder
``S``, elbow ``E`` and wrist ``W`` as joint centres: ``|S - E|`` and ``|E - W|`` the same at
every posture (:func:`wholebody.robot.arms.arm_chain` checks it). Turning a joint between two
of the points keeps their distance iff one of them is on the joint's axis. With ``S``, ``E``
and ``W`` fixed in the links after the arm's joints ``s < e < w`` (joints ``j_1 .. j_n`` from
the arm's first one, position 0 the link the first hangs from), the points are joint centres
iff, for some ``s <= k1 <= e <= k2 <= w``:

* ``S`` is on the axes of ``j_s+1 .. j_k1`` (a point fixed before them stays on an axis
  further down only if it is on every axis before it),
* ``E`` on the axes of ``j_k1+1 .. j_k2`` (the run around its own link),
* ``W`` on the axes of ``j_k2+1 .. j_w``.

:func:`suggest_centres` tries every ``(s, e, w, k1, k2)`` that keeps the arm's upper-arm and
forearm links between the points: for each point, the one with the least squared distance to
its axes nearest the arm's frame,

    p = argmin  sum_i |P_i (p - c_i)|^2 + eps |p - p_0|^2,    P_i = I - a_i a_i^T,

(axis ``i`` through ``c_i`` along the unit ``a_i``, ``p_0`` the frame's origin: ``eps`` makes it
``p_0`` projected on a single axis, ``p_0`` itself without one) at the neutral posture. A choice
is possible when each point is within :data:`ON_AXIS` of its axes (they meet). Of the possible
ones, the one whose points lie on the most axes is taken (joint centres where a joint's axes
meet: a shoulder where three meet beats one on a single axis), then the one with the most
points on an axis, then the one nearest the arm's frames; it is checked at random postures as
:mod:`~wholebody.robot.arms` checks. The points are given in the frame of their link, as
``[frames]`` entries of ``robot.toml``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from wholebody.robot.config import ArmConfig, RobotConfig
from wholebody.robot.parts import Frame

if TYPE_CHECKING:
    from wholebody.robot.robot import Robot

__all__ = ["ON_AXIS", "CentreSuggestion", "centres_text", "frames_toml", "suggest_centres"]

ON_AXIS = 2e-5
"""m: a point this close to a joint's axis is on it (URDF numbers are rounded to 0.1 mm or
finer; the arm check allows the lengths to vary by 0.1 mm)."""

KEYS = ("shoulder", "elbow", "wrist")
_EPS = 1e-9  # the pull towards the frame's own origin (1/m^2 against the axes' 1)
_MOVED = 1e-6  # m: a frame moved less than this stays


@dataclass(frozen=True)
class CentreSuggestion:
    """A joint centre for one frame of an arm: the ``[frames]`` entry ``name`` at ``xyz``
    (m) in ``link``, on the axes of ``axes``; ``offset`` (m) is how far the arm's frame
    ``frame`` is from it (0: the frame is a joint centre already)."""

    arm: str
    key: str
    frame: str
    name: str
    link: str
    xyz: tuple[float, float, float]
    axes: tuple[str, ...]
    offset: float

    @property
    def moved(self) -> bool:
        """Whether the arm's frame must be replaced by this one."""
        return self.offset > _MOVED


@dataclass(frozen=True)
class _Axis:
    joint: str
    point: np.ndarray  # a point of the axis (the joint's origin), world, m
    direction: np.ndarray  # unit


def suggest_centres(robot: Robot, cfg: ArmConfig) -> tuple[CentreSuggestion, ...] | None:
    """Shoulder, elbow and wrist joint centres of the arm ``cfg`` of ``robot`` (module
    docstring); None when there are none (axes that do not meet where they would have to).
    ``robot`` needs the arm's frames, not the arm (a robot loaded without ``[arms]`` will
    do)."""
    model, data = robot.model, robot.model.createData()
    pin.computeJointJacobians(model, data, robot.neutral())
    pin.updateFramePlacements(model, data)
    frames = [robot.frame(getattr(cfg, k)) for k in KEYS]
    joints = _arm_joints(robot, cfg)
    axes = [_axis(model, data, j) for j in joints]
    links = [model.parents[joints[0]], *joints] if joints else []  # position -> joint id
    origins = [data.oMf[f.index].translation.copy() for f in frames]
    for positions, points, sets in _candidates(robot, cfg, links, axes, origins):
        out = tuple(
            _suggestion(
                robot, data, cfg, k, frames[i], links[positions[i]], points[i], sets[i], origins[i]
            )
            for i, k in enumerate(KEYS)
        )
        if _passes(robot, out):
            return out
    return None


def _arm_joints(robot: Robot, cfg: ArmConfig) -> list[int]:
    """The joints that move the arm's tool from the arm's first one, root side first: its
    group's first joint, else the first below the shoulder frame (a torso's joints are no
    shoulder's)."""
    model = robot.model
    chain = [j for j in model.supports[robot.frame(cfg.tool).joint] if model.joints[j].nv == 1]
    if cfg.group is None:
        above = set(model.supports[robot.frame(cfg.shoulder).joint])
        return [j for j in chain if j not in above]
    ids = {model.getJointId(n) for n in robot.config.groups[cfg.group] if model.existJointName(n)}
    first = next((i for i, j in enumerate(chain) if j in ids), 0)
    return chain[first:]


_Choice = tuple[tuple[int, int, int], list[np.ndarray], tuple[list[_Axis], ...]]
"""Link positions of shoulder, elbow and wrist, their points (world, m) and axis sets."""


def _candidates(
    robot: Robot,
    cfg: ArmConfig,
    links: list[int],
    axes: list[_Axis | None],
    origins: list[np.ndarray],
) -> list[_Choice]:
    """The possible choices (module docstring) as ``(link positions, points, axis sets)``,
    best first."""
    found = []
    allowed = _allowed(robot, cfg, links)
    for s, e, w in itertools.combinations(range(len(links)), 3):
        if not (s in allowed[0] and e in allowed[1] and w in allowed[2]):
            continue
        if any(a is None for a in axes[s:w]):  # a prismatic joint changes the lengths
            continue
        for k1, k2 in itertools.product(range(s, e + 1), range(e, w + 1)):
            sets = (axes[s:k1], axes[k1:k2], axes[k2:w])
            points = [_nearest(x, p0) for x, p0 in zip(sets, origins, strict=True)]  # type: ignore[arg-type]
            if any(_residual(x, p) > ON_AXIS for x, p in zip(sets, points, strict=True)):  # type: ignore[arg-type]
                continue
            moves = sum(
                float(np.linalg.norm(p - p0)) for p, p0 in zip(points, origins, strict=True)
            )
            score = (-(w - s), -sum(bool(x) for x in sets), moves)
            found.append((score, (s, e, w), points, sets))
    found.sort(key=lambda c: c[0])
    return [(positions, points, sets) for _, positions, points, sets in found]


def _allowed(robot: Robot, cfg: ArmConfig, links: list[int]) -> tuple[set[int], ...]:
    """The link positions the shoulder, elbow and wrist may take: the upper-arm links below
    the shoulder and above the elbow, the forearm links below the elbow and above the
    wrist, the wrist above the tool (as :mod:`~wholebody.robot.arms` checks)."""
    supports = robot.model.supports

    def below(a: int, b: int) -> bool:
        return a in supports[b]

    upper = [robot.frame(n).joint for n in cfg.upper_arm]
    fore = [robot.frame(n).joint for n in cfg.forearm]
    tool = robot.frame(cfg.tool).joint
    positions = range(len(links))
    return (
        {i for i in positions if all(below(links[i], b) for b in upper)},
        {
            i
            for i in positions
            if all(below(b, links[i]) for b in upper) and all(below(links[i], b) for b in fore)
        },
        {i for i in positions if all(below(b, links[i]) for b in fore) and below(links[i], tool)},
    )


def _axis(model: pin.Model, data: pin.Data, j: int) -> _Axis | None:
    """Joint ``j``'s axis in the world at the computed posture; None for a joint that does
    not turn (prismatic)."""
    jm = model.joints[j]
    local = pin.getJointJacobian(model, data, j, pin.LOCAL)[:, jm.idx_v]
    if jm.nv != 1 or np.linalg.norm(local[3:]) < 1e-9:
        return None
    M = data.oMi[j]
    a = M.rotation @ local[3:]
    return _Axis(model.names[j], M.translation.copy(), a / np.linalg.norm(a))


def _nearest(axes: list[_Axis], p0: np.ndarray) -> np.ndarray:
    """The point with the least squared distance to ``axes``, pulled towards ``p0``."""
    A, b = _EPS * np.eye(3), _EPS * p0
    for ax in axes:
        P = np.eye(3) - np.outer(ax.direction, ax.direction)
        A, b = A + P, b + P @ ax.point
    return np.linalg.solve(A, b)


def _residual(axes: list[_Axis], p: np.ndarray) -> float:
    """The largest distance (m) from ``p`` to one of ``axes`` (0 without any)."""
    return max(
        (float(np.linalg.norm(np.cross(p - ax.point, ax.direction))) for ax in axes), default=0.0
    )


def _suggestion(
    robot: Robot,
    data: pin.Data,
    cfg: ArmConfig,
    key: str,
    frame: Frame,
    joint: int,
    point: np.ndarray,
    axes: list[_Axis],
    origin: np.ndarray,
) -> CentreSuggestion:
    """The world ``point`` as a frame in the link that ``joint`` moves."""
    link = _link_of(robot, joint)
    local = data.oMf[robot.frame(link).index].actInv(point)
    name = f"{cfg.name}_{key}_centre"  # a new name: pasted, it replaces no table
    while robot.model.existFrame(name):
        name += "_"
    xyz = tuple(round(float(v), 6) + 0.0 for v in local)
    return CentreSuggestion(
        cfg.name,
        key,
        frame.name,
        name,
        link,
        xyz,  # type: ignore[arg-type]
        tuple(a.joint for a in axes),
        float(np.linalg.norm(point - origin)),
    )


def _link_of(robot: Robot, joint: int) -> str:
    """The link a joint moves (its URDF child), the root link for the world or a root joint."""
    name = robot.model.names[joint]
    return robot.urdf.children.get(name, robot.urdf.root) if joint > 0 else robot.urdf.root


def _passes(robot: Robot, points: tuple[CentreSuggestion, ...]) -> bool:
    """Whether the suggested points keep the shoulder-elbow and elbow-wrist distances to
    0.1 mm (distinct by 1 mm) at the neutral posture and 20 random ones of the arm's
    joints, as the arm check does."""
    supports, model = robot.model.supports, robot.model
    joints = [robot.frame(s.link).joint for s in points]
    above = set(supports[joints[0]])
    moving = [model.joints[j] for j in supports[joints[2]] if j not in above]
    idx = [i for jm in moving for i in range(jm.idx_q, jm.idx_q + jm.nq)]
    rng, neutral = np.random.default_rng(1), robot.neutral()
    data = model.createData()
    lengths = []
    for k in range(21):
        q = neutral.copy()
        if k:
            q[idx] = robot.random_configuration(rng)[idx]
        pin.framesForwardKinematics(model, data, q)
        p = [data.oMf[robot.frame(s.link).index].act(np.array(s.xyz)) for s in points]
        lengths.append((np.linalg.norm(p[1] - p[0]), np.linalg.norm(p[2] - p[1])))
    d = np.array(lengths)
    return bool(d[0].min() >= 1e-3 and np.all(d.max(axis=0) - d.min(axis=0) <= 1e-4))


def frames_toml(suggestions: tuple[CentreSuggestion, ...]) -> str:
    """The ``[frames]`` entries of the frames to move, in robot.toml syntax, then (as a
    comment) the ``[arms]`` keys to point at them."""
    moved = [s for s in suggestions if s.moved]
    if not moved:
        return ""
    lines = []
    for s in moved:
        xyz = ", ".join(repr(v) for v in s.xyz)
        on = ", ".join(s.axes) or "no joint between the frames"
        lines += [
            f"# {s.arm} {s.key}: on the axes of {on}; {s.frame!r} is "
            f"{1e3 * s.offset:.1f} mm from it",
            f"[frames.{s.name}]",
            f'parent = "{s.link}"',
            f"xyz = [{xyz}]",
            "",
        ]
    keys = ", ".join(f'{s.key} = "{s.name}"' for s in moved if s.name != s.frame)
    if keys:
        lines.append(f"# and in [arms.{moved[0].arm}]: {keys}")
    return "\n".join(lines).rstrip() + "\n"


def centres_text(config: RobotConfig) -> str:
    """For each arm of ``config``: nothing to do when its frames pass the arm check, else the
    ``[frames]`` entries of :func:`frames_toml` (robot.toml syntax, with comments), or why
    there are none. The robot is loaded without its ``[arms]`` (which its frames fail)."""
    from wholebody.errors import ConfigError
    from wholebody.robot.arms import arm_chain
    from wholebody.robot.robot import Robot

    robot = Robot(replace(config, arms={}))
    parts = []
    for name, cfg in config.arms.items():
        try:
            arm_chain(robot, cfg)
        except ConfigError as exc:
            found = suggest_centres(robot, cfg)
            parts.append(
                frames_toml(found)
                if found
                else f"# arm {name}: {exc}\n# no joint centres found: the axes of its "
                "joints do not meet where they would have to\n"
            )
        else:
            parts.append(
                f"# arm {name}: its shoulder, elbow and wrist frames are joint centres already\n"
            )
    return "\n".join(parts) if parts else "# no [arms] in robot.toml\n"
