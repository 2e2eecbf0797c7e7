"""What wholebody reads from a URDF itself, besides Pinocchio: link masses and centres of mass,
mimic joints, numbers checked, and ``package://`` paths resolved.

Pinocchio loads the kinematics; this module reads the same file as XML for what it needs to
check or that Pinocchio does not keep per link (masses and centres of mass before any joint is
locked, the ``<mimic>`` of a joint). Only ``<link>`` and ``<joint>`` children of ``<robot>`` are
read: ``<transmission>``, ``<gazebo>`` and other extensions are ignored (a transmission's
``<joint>`` element is not a joint).

``package://PKG/rest`` (a ROS package path) resolves to ``DIR/PKG/rest`` for the first
directory ``DIR`` in: the robot.toml's ``package_dirs``, ``$ROS_PACKAGE_PATH``, and the share
directory of the installed ``example-robot-data`` package (``pip install '.[robots]'`` from
a checkout), which holds the package ``example-robot-data``.
"""

from __future__ import annotations

import difflib
import importlib.metadata
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wholebody.errors import ModelError

__all__ = [
    "MeshRef",
    "Mimic",
    "UrdfInfo",
    "example_robot_data_share",
    "read_urdf",
    "resolve_package",
]

PACKAGE = "package://"
ROBOT_DATA = "example-robot-data"
ROBOT_DATA_HINT = "pip install '.[robots]' from the checkout (the example-robot-data package)"


@dataclass(frozen=True)
class Mimic:
    """A joint that follows another: ``q = multiplier q_leader + offset`` (rad or m)."""

    leader: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class UrdfInfo:
    """The URDF's links (mass kg, centre of mass m in the link frame), its root link, each
    joint's type and the mimic joints that move (a fixed joint's ``<mimic>`` is ignored, as
    Pinocchio ignores it)."""

    links: dict[str, tuple[float, np.ndarray]]
    root: str
    joint_types: dict[str, str]
    mimic: dict[str, Mimic]
    children: dict[str, str]
    """Each joint's child link."""
    radii: dict[str, float]
    """Per link with a cylinder or sphere in its collision (else visual) geometry, the
    largest radius (m): what a wheel's radius is checked against."""
    meshes: dict[str, tuple[MeshRef, ...]] = field(default_factory=dict)
    """Per link without a cylinder or sphere, the meshes of its collision (else visual)
    geometry: what a wheel given as a mesh is checked against."""


@dataclass(frozen=True)
class MeshRef:
    """A ``<mesh>`` of a link: its file as written (a ``package://`` path, or relative to the
    URDF), its scale, and its placement in the link frame (``<origin>``; m, rad)."""

    filename: str
    scale: tuple[float, float, float]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]


def example_robot_data_share() -> Path | None:
    """The directory holding the installed ``example-robot-data`` package (its
    ``cmeel.prefix/share``), or None when it is not installed."""
    try:
        files = importlib.metadata.files(ROBOT_DATA) or []
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in files:  # .../share/example-robot-data/robots/...
        parts = Path(str(f)).parts
        for i in range(len(parts) - 2):
            if parts[i] == "share" and parts[i + 1] == ROBOT_DATA:
                located = Path(str(f.locate()))
                return located.parents[len(parts) - i - 2]
    return None


def package_search_path(dirs: Sequence[Path]) -> list[Path]:
    """Where ``package://`` paths are looked up, in order (see the module docstring)."""
    out = list(dirs)
    out += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    share = example_robot_data_share()
    if share is not None:
        out.append(share)
    return out


def resolve_package(uri: str, dirs: Sequence[Path]) -> Path:
    """The file a ``package://PKG/rest`` path names (searched in :func:`package_search_path`),
    a plain path unchanged. :class:`FileNotFoundError`: for a package found without the
    file, the part of the path that is missing and the nearest names there (a typo); for a
    package not found, what was searched, the nearest package names and, for
    ``example-robot-data``, the install command."""
    if not uri.startswith(PACKAGE):
        return Path(uri)
    rest = uri[len(PACKAGE) :]
    package = rest.split("/", 1)[0]
    search = package_search_path(dirs)
    for d in search:
        if (d / rest).exists():
            return d / rest
    found = [d / package for d in search if (d / package).is_dir()]
    if found:
        raise FileNotFoundError(
            f"{uri}: package {package!r} is at {found[0]}, but "
            + _missing_file(found[0], rest.split("/")[1:])
        )
    hint = f"; install it with {ROBOT_DATA_HINT}" if package == ROBOT_DATA else ""
    known = [p.name for d in search if d.is_dir() for p in d.iterdir() if p.is_dir()]
    close = difflib.get_close_matches(package, known, n=3, cutoff=0.6)
    hint += f"; nearest packages there: {', '.join(close)}" if close else ""
    where = ", ".join(str(d) for d in search) or "no package directories"
    raise FileNotFoundError(f"{uri}: package {package!r} not found (searched {where}){hint}")


def _missing_file(package: Path, parts: Sequence[str]) -> str:
    """Which part of a path inside an existing package directory is missing, with the
    names nearest to it in the directory above it (a typo in a file name)."""
    here = package
    for k, part in enumerate(parts):
        if not (here / part).exists():
            names = sorted(p.name for p in here.iterdir()) if here.is_dir() else []
            close = difflib.get_close_matches(part, names, n=3, cutoff=0.5)
            near = f"; nearest names there: {', '.join(close)}" if close else ""
            inside = "/".join(parts[:k]) or "its top directory"
            return f"{inside} has no {part!r}{near}"
        here = here / part
    return f"{'/'.join(parts)} is not there"


def read_urdf(path: Path, text: str | None = None) -> UrdfInfo:
    """Links, root, joint types and moving mimic joints of a URDF, its numbers checked
    (:class:`ModelError` naming the file and element); ``text``: the file's content as
    ``robot.toml`` changed it (:mod:`wholebody.robot.overrides`), read instead of it."""
    try:
        root = ET.fromstring(text) if text is not None else ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ModelError(f"{path}: not well-formed XML: {exc}") from exc
    if root.tag != "robot":
        raise ModelError(f"{path}: root element is <{root.tag}>; expected <robot>")
    links: dict[str, tuple[float, np.ndarray]] = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise ModelError(f"{path}: a <link> has no name attribute")
        links[name] = _inertial(path, name, link.find("inertial"))
    types: dict[str, str] = {}
    mimic: dict[str, Mimic] = {}
    for joint in root.findall("joint"):
        _check_joint(path, joint)
        name, kind = str(joint.get("name")), str(joint.get("type"))
        types[name] = kind
        m = joint.find("mimic")
        if m is not None and kind != "fixed":
            mimic[name] = _mimic(path, name, m)
    for name, m in mimic.items():
        if m.leader not in types or types[m.leader] == "fixed":
            raise ModelError(
                f"{path}: joint {name!r} mimics {m.leader!r}, which is not a moving "
                "joint of the URDF"
            )
        if m.leader in mimic:
            raise ModelError(
                f"{path}: joint {name!r} mimics {m.leader!r}, itself a mimic "
                "joint: give it the first leader of the chain"
            )
    child_of = {
        str(j.get("name")): str(c.get("link"))
        for j in root.findall("joint")
        for c in j.findall("child")
    }
    roots = [name for name in links if name not in set(child_of.values())]
    if len(roots) != 1:
        raise ModelError(f"{path}: expected one root link, found {roots or 'none'}")
    radii = _radii(root)
    return UrdfInfo(links, roots[0], types, mimic, child_of, radii, _meshes(path, root, radii))


def _radii(root: ET.Element) -> dict[str, float]:
    """Largest cylinder or sphere radius of each link's collision geometry (else visual)."""
    out: dict[str, float] = {}
    for link in root.findall("link"):
        for tag in ("collision", "visual"):
            r = [
                float(g.get("radius", "nan"))
                for e in link.findall(tag)
                for g in (e.find("geometry/cylinder"), e.find("geometry/sphere"))
                if g is not None
            ]
            r = [v for v in r if np.isfinite(v) and v > 0]
            if r:
                out[str(link.get("name"))] = max(r)
                break
    return out


def _meshes(
    path: Path, root: ET.Element, radii: dict[str, float]
) -> dict[str, tuple[MeshRef, ...]]:
    """The meshes of each link that :func:`_radii` found no radius for: its collision
    geometry's, else its visual geometry's."""
    out: dict[str, tuple[MeshRef, ...]] = {}
    for link in root.findall("link"):
        name = str(link.get("name"))
        if name in radii:
            continue
        for tag in ("collision", "visual"):
            refs = tuple(
                _mesh_ref(path, name, e)
                for e in link.findall(tag)
                if e.find("geometry/mesh") is not None
            )
            if refs:
                out[name] = refs
                break
    return out


def _mesh_ref(path: Path, link: str, element: ET.Element) -> MeshRef:
    """The ``<mesh>`` of a ``<collision>`` or ``<visual>`` element, its numbers checked (as
    urdfdom checks them: three each)."""
    mesh, origin = element.find("geometry/mesh"), element.find("origin")
    assert mesh is not None
    where = f"link {link!r} <mesh"

    def numbers(e: ET.Element | None, key: str, default: str) -> tuple[float, float, float]:
        text = e.get(key, default) if e is not None else default
        return tuple(float(v) for v in _numbers(path, f"{where} {key}>", text, 3))  # type: ignore[return-value]

    return MeshRef(
        mesh.get("filename", ""),
        numbers(mesh, "scale", "1 1 1"),
        numbers(origin, "xyz", "0 0 0"),
        numbers(origin, "rpy", "0 0 0"),
    )


def _mimic(path: Path, name: str, element: ET.Element) -> Mimic:
    leader = element.get("joint")
    if not leader:
        raise ModelError(f"{path}: joint {name!r}: <mimic> has no joint attribute")
    where = f"joint {name!r} <mimic"
    multiplier = float(_numbers(path, f"{where} multiplier>", element.get("multiplier", "1"), 1)[0])
    offset = float(_numbers(path, f"{where} offset>", element.get("offset", "0"), 1)[0])
    if multiplier == 0.0:
        raise ModelError(
            f"{path}: joint {name!r}: <mimic multiplier> is 0: the joint would "
            "never move; make it fixed"
        )
    return Mimic(leader, multiplier, offset)


def _numbers(path: Path, where: str, text: str, size: int) -> np.ndarray:
    """``size`` finite numbers from a URDF attribute, or :class:`ModelError`."""
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError as exc:
        raise ModelError(f"{path}: {where}: {text!r} is not {size} numbers") from exc
    if values.shape != (size,) or not np.isfinite(values).all():
        raise ModelError(f"{path}: {where}: expected {size} finite numbers, got {text!r}")
    return values


def _inertial(path: Path, link: str, inertial: ET.Element | None) -> tuple[float, np.ndarray]:
    """A link's mass (kg, finite, >= 0) and centre of mass (link frame, m); 0 without
    ``<inertial>``. The inertia tensor's entries must be finite."""
    mass, com = 0.0, np.zeros(3)
    if inertial is not None:
        where = f"link {link!r} <inertial>"
        m, o, inertia = inertial.find("mass"), inertial.find("origin"), inertial.find("inertia")
        if m is not None:
            mass = float(_numbers(path, f"{where} <mass value>", m.get("value", "0"), 1)[0])
            if mass < 0:
                raise ModelError(f"{path}: {where}: mass {mass:g} kg is negative")
        if o is not None:
            com = _numbers(path, f"{where} <origin xyz>", o.get("xyz", "0 0 0"), 3)
        if inertia is not None:
            for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                _numbers(path, f"{where} <inertia {key}>", inertia.get(key, "0"), 1)
    com.setflags(write=False)
    return mass, com


def _check_joint(path: Path, joint: ET.Element) -> None:
    """A joint's origin is finite; a moving joint has a non-zero axis and finite limits with
    a velocity limit >= 0 (0: not given). A negative one would be read as no limit at all."""
    name, kind = joint.get("name"), joint.get("type")
    where = f"joint {name!r}"
    origin = joint.find("origin")
    if origin is not None:
        _numbers(path, f"{where} <origin xyz>", origin.get("xyz", "0 0 0"), 3)
        _numbers(path, f"{where} <origin rpy>", origin.get("rpy", "0 0 0"), 3)
    if kind in ("fixed", "floating", "planar"):
        return
    axis = joint.find("axis")
    if axis is not None:
        xyz = _numbers(path, f"{where} <axis xyz>", axis.get("xyz", "1 0 0"), 3)
        if not np.linalg.norm(xyz) > 1e-9:
            raise ModelError(
                f"{path}: {where}: <axis xyz> is zero: the joint would move "
                "nothing; give its axis or make it fixed"
            )
    limit = joint.find("limit")
    if limit is None:
        return
    for key in ("lower", "upper", "effort", "velocity"):
        if key in limit.attrib:
            value = float(_numbers(path, f"{where} <limit {key}>", limit.get(key, ""), 1)[0])
            if key in ("effort", "velocity") and value < 0:
                raise ModelError(
                    f"{path}: {where}: <limit {key}> = {value:g} is negative (0 means not given)"
                )
