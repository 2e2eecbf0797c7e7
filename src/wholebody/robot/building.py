"""From ``robot.toml`` and its URDF to the Pinocchio model the robot runs on.

1. The URDF is loaded whole by Pinocchio (a planar root joint for a mobile base, a free
   flyer for a floating one), as ``[joints]`` changed it (:mod:`wholebody.robot.overrides`),
   its root placed at ``[base] height`` above the floor.
2. ``[locked]`` joints leave the model: Pinocchio's reduced model
   (``pinocchio.buildReducedModel``) welds each at its position, so casters, fingers,
   suspensions or legs are no velocities of ``u`` and cost nothing in a step (TIAGo++ as
   shipped has 101 velocities; 19 with its hands, casters and suspensions locked). A mimic joint
   whose leader is locked is locked with it, at ``multiplier * value + offset``.
3. ``[frames]`` are added as operational frames, on a link or joint of the (reduced) model.

Geometry for drawing (:func:`geometry_model`) is reduced the same way, so that it matches the
model frame for frame.
"""

from __future__ import annotations

import fnmatch
import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pinocchio as pin

from wholebody.errors import ModelError
from wholebody.robot.config import RobotConfig
from wholebody.robot.urdf import UrdfInfo, package_search_path

__all__ = ["Built", "build_model", "geometry_model"]


class Built:
    """The model to run on, and how it came from the URDF's: ``locked`` maps each locked
    joint to its position (rad, m), ``locked_groups`` the ``[groups]`` locked whole."""

    def __init__(
        self,
        model: pin.Model,
        full: pin.Model,
        locked: dict[str, float],
        locked_groups: tuple[str, ...],
        reference: np.ndarray,
    ) -> None:
        self.model, self.full, self.locked = model, full, locked
        self.locked_groups, self.reference = locked_groups, reference


def build_model(
    config: RobotConfig, info: UrdfInfo, mobile: bool, text: str | None = None
) -> Built:
    """The robot's Pinocchio model: the URDF (``text``: as ``[joints]`` changed it), its root
    placed at ``[base] height``, locked joints removed, declared frames added."""
    full = _load(config, mobile, text)
    if config.base.height:
        _raise_root(full, config.base.height)
    locked, groups = _resolve_locked(config, info, full, mobile)
    reference = _reference(full, locked)
    ids = [full.getJointId(name) for name in locked]
    model = _reduced(full, ids, reference) if ids else full
    for frame in config.frames.values():
        _add_frame(config, model, frame.name, frame.parent, frame.xyz, frame.rpy)
    return Built(model, full, locked, groups, reference)


def geometry_model(
    config: RobotConfig, built: Built, kind: pin.GeometryType
) -> tuple[pin.GeometryModel, str]:
    """The URDF's visual or collision geometry matching ``built.model`` (meshes found through
    the package search path), and a note: empty, or, where a mesh cannot be found, what was
    left out (the geometry is then the URDF's shapes without any mesh)."""
    dirs = [str(d) for d in package_search_path(config.package_dirs)]
    note = ""
    try:
        geom = pin.buildGeomFromUrdf(built.full, str(config.urdf), kind, package_dirs=dirs)
    except ValueError as exc:  # Pinocchio's message names the mesh it could not find
        text, dropped = _without_meshes(config.urdf)
        geom = pin.buildGeomFromUrdfString(built.full, text, kind, package_dirs=dirs)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "a mesh is missing"
        note = (
            f"{config.urdf.name}: {dropped} meshes not drawn ({first}); give their "
            "directory in [robot] package_dirs"
        )
    if built.locked:
        ids = [built.full.getJointId(name) for name in built.locked]
        geom = _reduced(built.full, ids, built.reference, geom)
    return geom, note


def _without_meshes(urdf: Path) -> tuple[str, int]:
    """The URDF's text with every ``<visual>`` and ``<collision>`` that holds a mesh removed,
    and how many were."""
    tree = ET.parse(urdf)
    dropped = 0
    for link in tree.getroot().findall("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                if element.find("geometry/mesh") is not None:
                    link.remove(element)
                    dropped += 1
    return ET.tostring(tree.getroot(), encoding="unicode"), dropped


_RENAMED = "#link"


def _reduced(
    full: pin.Model, ids: list[int], reference: np.ndarray, geom: pin.GeometryModel | None = None
) -> pin.Model:
    """``pinocchio.buildReducedModel`` (of the model, or with ``geom`` of the geometry,
    returned alone), for a URDF where a link and a joint share a name too (Pinocchio's
    reduction looks frames up by name alone and refuses the ambiguity): such links' frames
    are renamed while it runs, on a copy."""
    model = full.copy()
    names = [f.name for f in model.frames]
    shared = {n for n in names if names.count(n) > 1}
    for i, f in enumerate(model.frames):
        if f.name in shared and f.type == pin.FrameType.BODY:
            model.frames[i].name = f.name + _RENAMED
    if geom is not None:
        return pin.buildReducedModel(model, geom, ids, reference)[1]
    reduced = pin.buildReducedModel(model, ids, reference)
    for i, f in enumerate(reduced.frames):
        if f.name.endswith(_RENAMED):
            reduced.frames[i].name = f.name[: -len(_RENAMED)]
    return reduced


def _load(config: RobotConfig, mobile: bool, text: str | None) -> pin.Model:
    """The URDF (or ``text``, its content changed) as a Pinocchio model, with a planar root
    joint for a mobile base (a free flyer for a floating one)."""
    if config.base.type == "floating":
        root: tuple[pin.JointModel, ...] = (pin.JointModelFreeFlyer(),)
    else:
        root = (pin.JointModelPlanar(),) if mobile else ()
    try:
        if text is not None:
            return pin.buildModelFromXML(text, *root)
        return pin.buildModelFromUrdf(str(config.urdf), *root)
    except (RuntimeError, ValueError) as exc:
        raise ModelError(f"{config.urdf}: Pinocchio cannot load this URDF: {exc}") from exc


def _raise_root(model: pin.Model, height: float) -> None:
    """Place the root link ``height`` (m) above the world origin, in place: what hangs from
    the world (the planar root joint of a mobile base, or a fixed base's first joints, its
    root link's frames and mass) is moved up by ``height``. The world frame stays where it
    is: the floor is its plane z = 0."""
    up = pin.SE3(np.eye(3), np.array([0.0, 0.0, height]))
    for j in range(1, model.njoints):
        if model.parents[j] == 0:
            model.jointPlacements[j] = up * model.jointPlacements[j]
    for i, frame in enumerate(model.frames):
        if i > 0 and frame.parentJoint == 0:
            model.frames[i].placement = up * frame.placement
    model.inertias[0] = model.inertias[0].se3Action(up)


def _resolve_locked(
    config: RobotConfig, info: UrdfInfo, full: pin.Model, mobile: bool
) -> tuple[dict[str, float], tuple[str, ...]]:
    """``[locked]`` expanded to joints (names, patterns, groups, in the file's order; a later
    key overrides an earlier one for the same joint), with the followers of locked leaders."""
    joints = list(full.names)[2 if mobile else 1 :]  # below the universe and a root joint
    locked: dict[str, float] = {}
    groups: list[str] = []
    for key, value in config.locked.items():
        if key in config.groups:
            matched = list(config.groups[key])
            groups.append(key)
        else:
            matched = [j for j in joints if fnmatch.fnmatchcase(j, key)]
        if not matched:
            raise config.error(
                f"locked.{key}",
                "matches no joint of the URDF and is not a "
                "group: expected a joint, a glob pattern or a group",
            )
        for j in matched:
            if j not in joints:
                raise config.error(f"locked.{key}", f"{j!r} is not a moving joint of the URDF")
            locked[j] = value
    for follower, m in info.mimic.items():
        if m.leader in locked and follower not in locked:
            locked[follower] = m.multiplier * locked[m.leader] + m.offset
    for j, value in locked.items():
        _check_inside(config, full, j, value)
    return locked, tuple(groups)


def _check_inside(config: RobotConfig, full: pin.Model, joint: str, value: float) -> None:
    jm = full.joints[full.getJointId(joint)]
    if jm.nq != 1:  # continuous: any angle
        return
    lo, hi = full.lowerPositionLimit[jm.idx_q], full.upperPositionLimit[jm.idx_q]
    if not lo - 1e-9 <= value <= hi + 1e-9:
        raise config.error(
            "locked", f"joint {joint!r} locked at {value:g}, outside its limits [{lo:g}, {hi:g}]"
        )


def _reference(full: pin.Model, locked: Mapping[str, float]) -> np.ndarray:
    """The configuration the locked joints are welded at (the others at Pinocchio's neutral)."""
    q = pin.neutral(full)
    for name, value in locked.items():
        jm = full.joints[full.getJointId(name)]
        if jm.nq == 2:
            q[jm.idx_q : jm.idx_q + 2] = math.cos(value), math.sin(value)
        else:
            q[jm.idx_q] = value
    return q


def _add_frame(
    config: RobotConfig,
    model: pin.Model,
    name: str,
    parent: str,
    xyz: tuple[float, ...],
    rpy: tuple[float, ...],
) -> None:
    """An operational frame ``name`` at ``(xyz, rpy)`` in the frame of link or joint
    ``parent``."""
    where = f"frames.{name}"
    if any(f.name == name for f in model.frames):
        raise config.error(where, f"the model already has a frame {name!r}: choose another name")
    index = None
    for kind in (pin.FrameType.BODY, pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT):
        if model.existFrame(parent, kind):
            index = model.getFrameId(parent, kind)
            break
    if index is None:
        raise config.error(f"{where}.parent", f"{parent!r} is no link or joint of the model")
    base = model.frames[index]
    local = pin.SE3(pin.rpy.rpyToMatrix(np.array(rpy)), np.array(xyz))
    model.addFrame(
        pin.Frame(name, base.parentJoint, index, base.placement * local, pin.FrameType.OP_FRAME)
    )
