"""A small URDF writer for robots described by tables (DH rows, link lengths, masses).

It is what the generators in ``robots/*/generate.py`` use, so that a robot's table stays
the single source of truth and its URDF is a build product. Geometry is limited to URDF
primitives (box, cylinder, sphere), which MeshCat and MuJoCo both load.

All lengths in metres, angles in radians, masses in kilograms, inertias in kg m^2.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from xml.sax.saxutils import quoteattr

import numpy as np

__all__ = [
    "Inertial",
    "Joint",
    "Link",
    "Shape",
    "ball_inertial",
    "box",
    "box_inertial",
    "frame_with_z",
    "mdh",
    "rod_inertial",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_from_matrix",
    "segment",
    "sphere",
    "trans",
    "urdf_document",
]


def rot_x(a: float) -> np.ndarray:
    """4x4 rotation about x by ``a`` rad."""
    c, s = math.cos(a), math.sin(a)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def rot_y(a: float) -> np.ndarray:
    """4x4 rotation about y by ``a`` rad."""
    c, s = math.cos(a), math.sin(a)
    T = np.eye(4)
    T[0, 0], T[0, 2], T[2, 0], T[2, 2] = c, s, -s, c
    return T


def rot_z(a: float) -> np.ndarray:
    """4x4 rotation about z by ``a`` rad."""
    c, s = math.cos(a), math.sin(a)
    T = np.eye(4)
    T[0:2, 0:2] = [[c, -s], [s, c]]
    return T


def trans(x: float, y: float, z: float) -> np.ndarray:
    """4x4 translation."""
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def mdh(alpha: float, a: float, d: float, theta: float) -> np.ndarray:
    """Modified (Craig) DH transform ``RotX(alpha) TransX(a) RotZ(theta) TransZ(d)``.

    With the joint variable q added to ``theta``, ``RotZ(theta + q) TransZ(d) =
    RotZ(theta) TransZ(d) RotZ(q)``: this transform is the URDF origin of a revolute joint
    whose axis is the child frame's z.
    """
    return rot_x(alpha) @ trans(a, 0.0, 0.0) @ rot_z(theta) @ trans(0.0, 0.0, d)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix (``R = Rz(yaw) Ry(pitch) Rx(roll)``).

    Entries below 1e-15 are set to +0 first, so that a half turn is always +pi (``atan2``
    turns the sign of a zero produced by rounding into the sign of pi)."""
    R = np.where(np.abs(R) < 1e-15, 0.0, R)
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(pitch)) < 1e-9:  # gimbal lock: put the whole turn in yaw
        angles = (0.0, pitch, math.atan2(-R[0, 1], R[1, 1]))
    else:
        angles = (math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0]))
    return tuple(_snap_quarter_turn(a) for a in angles)


def _snap_quarter_turn(angle: float) -> float:
    """``angle`` made an exact multiple of pi/2 when it is one to 1e-12 rad, so the generated
    file does not depend on the last bit of the platform's trigonometry."""
    k = round(angle / (math.pi / 2))
    return k * (math.pi / 2) if abs(angle - k * (math.pi / 2)) < 1e-12 else angle


def frame_with_z(direction: np.ndarray) -> np.ndarray:
    """A 3x3 rotation whose z axis is the unit vector along ``direction``."""
    z = np.asarray(direction, float) / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _fmt(values: Iterable[float]) -> str:
    """Shortest round-trip decimal of each value (so the URDF is exact); |v| < 1e-15 -> 0."""
    return " ".join(repr(0.0 if abs(v) < 1e-15 else float(v)) for v in values)


def _origin(T: np.ndarray) -> str:
    return f'<origin xyz="{_fmt(T[:3, 3])}" rpy="{_fmt(rpy_from_matrix(T[:3, :3]))}"/>'


@dataclass(frozen=True)
class Shape:
    """A visual and collision primitive placed in its link's frame.

    ``kind`` is ``"cylinder"`` (size = radius, length; axis = local z), ``"sphere"``
    (size = radius,) or ``"box"`` (size = x, y, z edge lengths).
    """

    kind: str
    placement: np.ndarray
    size: tuple[float, ...]
    material: str

    def xml(self) -> str:
        if self.kind == "cylinder":
            geo = f'<cylinder radius="{_fmt(self.size[:1])}" length="{_fmt(self.size[1:])}"/>'
        elif self.kind == "sphere":
            geo = f'<sphere radius="{_fmt(self.size)}"/>'
        elif self.kind == "box":
            geo = f'<box size="{_fmt(self.size)}"/>'
        else:
            raise ValueError(f"unknown shape kind {self.kind!r}: expected cylinder|sphere|box")
        pose = _origin(self.placement)
        return (
            f"    <visual>{pose}<geometry>{geo}</geometry>"
            f'<material name="{self.material}"/></visual>\n'
            f"    <collision>{pose}<geometry>{geo}</geometry></collision>\n"
        )


def segment(a: np.ndarray, b: np.ndarray, radius: float, material: str) -> Shape:
    """A cylinder between points a and b of the link frame."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    T = np.eye(4)
    T[:3, :3] = frame_with_z(b - a)
    T[:3, 3] = (a + b) / 2
    return Shape("cylinder", T, (radius, float(np.linalg.norm(b - a))), material)


def sphere(center: np.ndarray, radius: float, material: str) -> Shape:
    """A sphere at a point of the link frame."""
    return Shape("sphere", trans(*center), (radius,), material)


def box(center: np.ndarray, size: tuple[float, float, float], material: str) -> Shape:
    """An axis-aligned box (link axes) centred at a point of the link frame."""
    return Shape("box", trans(*center), tuple(float(s) for s in size), material)


@dataclass(frozen=True)
class Inertial:
    """Mass, centre of mass (link frame) and 3x3 inertia about the centre of mass."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray

    def xml(self) -> str:
        terms = " ".join(
            f'{key}="{_fmt((self.inertia[i, j],))}"'
            for key, i, j in (
                ("ixx", 0, 0),
                ("ixy", 0, 1),
                ("ixz", 0, 2),
                ("iyy", 1, 1),
                ("iyz", 1, 2),
                ("izz", 2, 2),
            )
        )
        return (
            f'    <inertial><origin xyz="{_fmt(self.com)}" rpy="0 0 0"/>'
            f'<mass value="{_fmt((self.mass,))}"/><inertia {terms}/></inertial>\n'
        )


def rod_inertial(
    a: np.ndarray, b: np.ndarray, mass: float, radius: float, com_fraction: float
) -> Inertial:
    """A solid cylinder from a to b with its centre of mass at ``a + com_fraction (b - a)``.

    The inertia is the uniform cylinder's about its own centroid (the centre-of-mass
    fraction models motors near the joints without changing the tensor materially).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = float(np.linalg.norm(b - a))
    R = frame_with_z(b - a)
    side = mass * (3 * radius**2 + length**2) / 12
    principal = np.diag([side, side, mass * radius**2 / 2])
    return Inertial(mass, a + com_fraction * (b - a), R @ principal @ R.T)


def ball_inertial(center: np.ndarray, mass: float, radius: float) -> Inertial:
    """A solid sphere."""
    return Inertial(mass, np.asarray(center, float), np.eye(3) * 0.4 * mass * radius**2)


def box_inertial(center: np.ndarray, mass: float, size: tuple[float, float, float]) -> Inertial:
    """A solid axis-aligned box."""
    x, y, z = size
    return Inertial(
        mass,
        np.asarray(center, float),
        np.diag([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12,
    )


@dataclass(frozen=True)
class Link:
    """A URDF link: optional inertial and any number of shapes."""

    name: str
    inertial: Inertial | None = None
    shapes: tuple[Shape, ...] = field(default_factory=tuple)

    def xml(self) -> str:
        body = (self.inertial.xml() if self.inertial else "") + "".join(
            s.xml() for s in self.shapes
        )
        if not body:
            return f'  <link name="{self.name}"/>\n'
        return f'  <link name="{self.name}">\n{body}  </link>\n'


@dataclass(frozen=True)
class Joint:
    """A URDF joint (``revolute``, ``continuous``, ``prismatic`` or ``fixed``)."""

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    lower: float = 0.0
    upper: float = 0.0
    velocity: float = 0.0
    effort: float = 0.0

    def xml(self) -> str:
        s = (
            f'  <joint name="{self.name}" type="{self.kind}">\n'
            f'    <parent link="{self.parent}"/><child link="{self.child}"/>\n'
            f"    {_origin(self.origin)}\n"
        )
        if self.kind != "fixed":
            s += f'    <axis xyz="{_fmt(self.axis)}"/>\n'
            lim = f'effort="{_fmt((self.effort,))}" velocity="{_fmt((self.velocity,))}"'
            if self.kind in ("revolute", "prismatic"):
                lim = f'lower="{_fmt((self.lower,))}" upper="{_fmt((self.upper,))}" ' + lim
            s += f"    <limit {lim}/>\n"
        return s + "  </joint>\n"


def urdf_document(
    name: str,
    links: Iterable[Link],
    joints: Iterable[Joint],
    materials: Mapping[str, str],
    generator: str,
) -> str:
    """The URDF text of a robot; ``materials`` maps a name to an ``"r g b a"`` colour."""
    head = (
        '<?xml version="1.0"?>\n'
        f"<!-- GENERATED by {generator}; do not edit by hand. -->\n"
        f"<robot name={quoteattr(name)}>\n"
    )
    mats = "".join(
        f'  <material name="{n}"><color rgba="{c}"/></material>\n' for n, c in materials.items()
    )
    body = "".join(x.xml() for x in links) + "".join(j.xml() for j in joints)
    return head + mats + body + "</robot>\n"
