"""``[joints]`` of ``robot.toml``: a URDF's joint data overridden without editing the URDF.

A URDF the user does not own can be wrong in ways that keep a robot from running: a wheel
declared ``revolute`` without ``<limit lower upper>`` (Pinocchio reads the range as [0, 0],
so the wheel cannot turn), a velocity limit of 0, an effort limit missing (a physics run
needs one per joint). ``[joints.<name>]`` replaces, for the joints a name or glob pattern
matches, the type (``revolute``, ``continuous``, ``prismatic``) and any of the ``<limit>``
attributes ``lower``, ``upper`` (rad, m), ``velocity`` (rad/s, m/s) and ``effort``
(N m, N). The URDF is read as XML, changed in memory and handed to Pinocchio and to
:func:`~wholebody.robot.urdf.read_urdf` as text; the file itself is never written.
"""

from __future__ import annotations

import fnmatch
import xml.etree.ElementTree as ET

from wholebody.errors import ModelError
from wholebody.robot._names import suggest
from wholebody.robot.config import JOINT_TYPES, JointOverride, RobotConfig

__all__ = ["urdf_text"]

LIMIT_KEYS = ("lower", "upper", "velocity", "effort")


def urdf_text(config: RobotConfig) -> str | None:
    """The URDF's text with ``[joints]`` applied, in the file's order (a later key wins for
    a joint two keys match); None without ``[joints]``, the file then read as it is. A
    ``robot.toml`` error for a key that matches no joint or names a joint that does not
    move."""
    if not config.joints:
        return None
    try:
        root = ET.parse(config.urdf).getroot()
    except ET.ParseError as exc:
        raise ModelError(f"{config.urdf}: not well-formed XML: {exc}") from exc
    joints = {str(j.get("name")): j for j in root.findall("joint")}
    for override in config.joints:
        matched = [n for n in joints if fnmatch.fnmatchcase(n, override.key)]
        if not matched:
            raise config.error(
                f"joints.{override.key}",
                f"matches no joint of {config.urdf.name}" + suggest(override.key, joints),
            )
        for name in matched:
            _apply(config, override, name, joints[name])
    return ET.tostring(root, encoding="unicode")


def _apply(config: RobotConfig, o: JointOverride, name: str, joint: ET.Element) -> None:
    """One override on one ``<joint>`` element (in place)."""
    where = f"joints.{o.key}"
    kind = joint.get("type")
    if kind not in JOINT_TYPES:
        raise config.error(
            where,
            f"joint {name!r} is {kind} in the URDF: [joints] changes "
            f"moving joints ({', '.join(JOINT_TYPES)}); lock a joint you want "
            "held ([locked])",
        )
    kind = o.type or kind
    joint.set("type", kind)
    limit = joint.find("limit")
    if limit is None:  # urdfdom wants effort and velocity in every <limit>; 0: not given
        limit = ET.SubElement(joint, "limit", effort="0", velocity="0")
    for key in LIMIT_KEYS:
        value = getattr(o, key)
        if value is not None:
            limit.set(key, repr(value))
    if kind == "continuous":
        for key in ("lower", "upper"):
            limit.attrib.pop(key, None)
        return
    lower, upper = (float(limit.get(k, "0")) for k in ("lower", "upper"))
    if not lower < upper:
        raise config.error(
            where,
            f"joint {name!r} would have the range [{lower:g}, "
            f"{upper:g}] (the URDF's where [joints] gives no lower or upper): "
            "give both, lower < upper",
        )
