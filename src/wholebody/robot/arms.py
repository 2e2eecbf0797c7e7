"""Arm chains from ``robot.toml``'s ``[arms]``: frames and bodies resolved, and the geometry the
arm tasks assume checked on loading.

The arm angle, the posture mapping and the arm energy
(:class:`~wholebody.tasks.ArmPotentialEnergy`) take an arm as three joint centres -- shoulder,
elbow, wrist -- with a tool below them, the upper arm between shoulder and elbow and the
forearm between elbow and wrist. :func:`arm_chain` checks exactly that: the frames lie one
below the other on one kinematic chain, the segments' links between them, the arm's joint
group on the chain, and the shoulder-elbow and elbow-wrist distances the same at every
posture (so that the three frames are joint centres, not points on the links); where they
are not, the error says which frame is off and where a joint centre is
(:mod:`~wholebody.robot.centres`).
"""

from __future__ import annotations

import shlex
from typing import TYPE_CHECKING

import numpy as np

from wholebody.errors import FrameError
from wholebody.robot._names import suggest
from wholebody.robot.centres import suggest_centres
from wholebody.robot.config import ArmConfig
from wholebody.robot.parts import ArmChain, Body, Frame, JointGroup

if TYPE_CHECKING:
    from wholebody.robot.robot import Robot

__all__ = ["arm_chain"]


def arm_chain(robot: Robot, cfg: ArmConfig) -> ArmChain:
    """The arm ``cfg`` of ``robot``, checked (module docstring); a ``robot.toml`` error
    naming the key otherwise."""
    where = f"arms.{cfg.name}"
    frames = {}
    for key in ("shoulder", "elbow", "wrist", "tool"):
        try:
            frames[key] = robot.frame(getattr(cfg, key))
        except FrameError as exc:
            raise robot.config.error(f"{where}.{key}", str(exc)) from None
    segments = {
        key: _segment(robot, f"{where}.{key}", getattr(cfg, key))
        for key in ("upper_arm", "forearm")
    }
    group = robot.groups[cfg.group] if cfg.group else None
    _check_chain(robot, cfg, frames, segments, group)
    lengths = _arm_lengths(robot, cfg, frames)
    return ArmChain(
        cfg.name,
        cfg.side,
        frames["shoulder"],
        frames["elbow"],
        frames["wrist"],
        frames["tool"],
        segments["upper_arm"][0],
        segments["forearm"][0],
        group,
        upper_arm_bodies=segments["upper_arm"],
        forearm_bodies=segments["forearm"],
        _lengths=lengths,
    )


def _segment(robot: Robot, key: str, links: tuple[str, ...]) -> tuple[Body, ...]:
    """The bodies of an arm segment: links of the URDF with a mass (the arm energy sums the
    gravity of them all; see ArmPotentialEnergy)."""
    out = []
    config, known = robot.config, robot.urdf.links
    for name in links:
        if name not in known:
            raise config.error(
                key,
                f"{name!r} is not a link of {config.urdf.name}" + suggest(name, known),
            )
        mass, com = known[name]
        if mass <= 0:
            raise config.error(
                key,
                f"link {name!r} has no mass in the URDF: expected an <inertial> "
                "with mass > 0 (the arm energy needs it)",
            )
        out.append(Body(name, robot.frame(name), mass, com))
    return tuple(out)


def _check_chain(
    robot: Robot,
    cfg: ArmConfig,
    frames: dict[str, Frame],
    segments: dict[str, tuple[Body, ...]],
    group: JointGroup | None,
) -> None:
    """Shoulder, elbow, wrist and tool one below the other on one kinematic chain, the
    upper arm between shoulder and elbow, the forearm between elbow and wrist, and the
    arm's group made of joints of that chain."""
    supports = robot.model.supports
    where = f"arms.{cfg.name}"

    def below(upper: Frame, lower: Frame) -> bool:  # every joint moving upper moves lower
        return upper.joint in supports[lower.joint]

    order = (("shoulder", "elbow"), ("elbow", "wrist"), ("wrist", "tool"))
    for a, b in order:
        if not below(frames[a], frames[b]):
            raise robot.config.error(
                f"{where}.{b}",
                f"{frames[b].name!r} is not below the {a} {frames[a].name!r} on one "
                "kinematic chain: expected shoulder, elbow, wrist and tool in that order "
                "along the arm",
            )
    for key, (a, b) in (("upper_arm", ("shoulder", "elbow")), ("forearm", ("elbow", "wrist"))):
        for body in (s.frame for s in segments[key]):
            if not (below(frames[a], body) and below(body, frames[b])):
                raise robot.config.error(
                    f"{where}.{key}",
                    f"link {body.name!r} is not on the chain between the {a} "
                    f"{frames[a].name!r} and the {b} {frames[b].name!r}",
                )
    if group is not None:
        _check_group(robot, where, group, frames["tool"])


def _check_group(robot: Robot, where: str, group: JointGroup, tool: Frame) -> None:
    """The arm's group made of joints that move its tool."""
    model = robot.model
    chain = set(model.supports[tool.joint])
    # the base's actuators (wheels, a planar base's virtual joints) move every frame
    base = set(robot.base.wheel_joints)
    off = [
        j
        for j in group.joints
        if j not in base and model.existJointName(j) and model.getJointId(j) not in chain
    ]
    if off:
        raise robot.config.error(
            f"{where}.group",
            f"group {group.name!r} has joints that do not move the tool "
            f"{tool.name!r}: {', '.join(map(repr, off))}",
        )


def _arm_lengths(robot: Robot, cfg: ArmConfig, frames: dict[str, Frame]) -> tuple[float, float]:
    """Shoulder-elbow and elbow-wrist distances (m), checked to be the same (to 0.1 mm) at
    the neutral posture and with the arm's joints (those between shoulder and wrist) at 20
    random positions: the arm geometry (arm angle, posture mapping) takes the three
    frames as joint centres."""
    # only the joints between shoulder and wrist move, the others stay at neutral
    supports, neutral = robot.model.supports, robot.neutral()
    above = set(supports[frames["shoulder"].joint])
    moving = [robot.model.joints[j] for j in supports[frames["wrist"].joint] if j not in above]
    idx = np.concatenate(
        [np.arange(jm.idx_q, jm.idx_q + jm.nq) for jm in moving] or [np.zeros(0, dtype=int)]
    )
    rng = np.random.default_rng(0)
    configurations = [neutral]
    for _ in range(20):
        q = neutral.copy()
        q[idx] = robot.random_configuration(rng)[idx]
        configurations.append(q)
    pairs = (("shoulder", "elbow"), ("elbow", "wrist"))
    d = np.empty((len(configurations), 2))
    for i, q in enumerate(configurations):
        state = robot.update(q)
        for k, (a, b) in enumerate(pairs):
            d[i, k] = np.linalg.norm(state.position(frames[b]) - state.position(frames[a]))
    where = f"arms.{cfg.name}"
    if d[0].min() < 1e-3:
        raise robot.config.error(
            where,
            f"upper-arm/forearm lengths {tuple(d[0].tolist())} m: the shoulder, elbow and "
            "wrist frames must be distinct points",
        )
    spread = d.max(axis=0) - d.min(axis=0)
    for k, (a, b) in enumerate(pairs):
        if spread[k] > 1e-4:
            raise robot.config.error(
                f"{where}.{b}",
                f"the {a}-{b} distance changes with the posture ({d[:, k].min():.4f} to "
                f"{d[:, k].max():.4f} m): the shoulder, elbow and wrist frames must be joint "
                "centres (on the axes of the joints between them)" + _centres_hint(robot, cfg),
            )
    return float(d[0, 0]), float(d[0, 1])


def _centres_hint(robot: Robot, cfg: ArmConfig) -> str:
    """Which of the arm's frames are off its joint centres, by how much, and where the
    centres are (:func:`~wholebody.robot.centres.suggest_centres`); the command that prints
    them as ``[frames]`` entries."""
    found = suggest_centres(robot, cfg)
    if found is None:
        return (
            "; no points of its links are: the axes of the joints between them do not "
            "meet where they would have to"
        )
    off = [
        f"the {s.key} {s.frame!r} is {1e3 * s.offset:.1f} mm from one (on the axes of "
        f"{', '.join(s.axes) or 'no joint'}: xyz = [{', '.join(map(repr, s.xyz))}] in "
        f"link {s.link!r})"
        for s in found
        if s.moved
    ]
    where = shlex.quote(str(robot.config.path.parent.resolve()))
    return (
        f"; {'; '.join(off)}. `wholebody info {where} --suggest-frames` prints these "
        "as [frames] entries to paste into robot.toml"
    )
