"""MeshCat scenes: the robot from its URDF geometry, targets, paths, obstacles and props.

The viewer runs on a localhost-only server (:mod:`wholebody.viz.server`). The robot is drawn
by Pinocchio's MeshCat visualizer from the URDF's visual geometry; everything else is
meshcat primitives under ``/scene``. A run can be shown live (:meth:`Scene.show`, called
from the control loop) and replayed afterwards as a MeshCat animation
(:meth:`Scene.animate`), which the page plays with its own controls, and saved as one
standalone HTML file that opens without a server (:meth:`Scene.save_html`).

The camera frames what is drawn (:meth:`Scene.frame`; :meth:`Scene.animate` frames the
whole replay): meshcat 0.3's camera always orbits the world origin and its viewer has no
command to move that target, so the scene is shifted instead (everything drawn, the grid
and the axes), putting the middle of the run at the origin.
"""

from __future__ import annotations

import contextlib
import io
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import meshcat
import meshcat.animation
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from pinocchio.visualize import MeshcatVisualizer

from wholebody.files import write_text
from wholebody.robot import Robot
from wholebody.viz.server import LocalServer, start_server

__all__ = ["CAMERA_FOV_DEG", "Scene", "camera_view", "rgb"]

_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])

CAMERA_FOV_DEG = 75.0
"""The vertical field of view of meshcat's default camera (deg)."""
VIEW_DIRECTION = np.array([1.0, -0.8, 0.6]) / np.linalg.norm([1.0, -0.8, 0.6])
"""Where the camera looks from, seen from the target (world): in front of a robot facing +x,
on its right and above."""


def camera_view(
    points: np.ndarray,
    fov_deg: float = CAMERA_FOV_DEG,
    aspect: float = 1.0,
    margin: float = 0.3,
    min_distance: float = 2.5,
) -> tuple[np.ndarray, np.ndarray]:
    """The camera target and the camera's offset from it (both m, world) that keep every
    one of ``points`` (N, 3) in view: the target is the middle of their bounding box
    (grown by ``margin`` m), the camera on :data:`VIEW_DIRECTION` at the distance where the
    box's bounding sphere fits the narrower of the vertical field of view ``fov_deg`` and
    the horizontal one (``aspect`` = width / height of the page: 1 fits every page at least
    as wide as it is tall), at least ``min_distance`` m (a robot at rest is seen whole)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if not len(pts):
        return np.zeros(3), min_distance * VIEW_DIRECTION
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    radius = float(np.linalg.norm(hi - lo)) / 2
    half = math.radians(fov_deg) / 2
    narrow = min(half, math.atan(math.tan(half) * aspect))
    distance = max(radius / math.sin(narrow), min_distance)
    return (lo + hi) / 2, distance * VIEW_DIRECTION


def rgb(color: str | int | Sequence[float]) -> int:
    """A colour as meshcat's 0xRRGGBB integer from ``"#rrggbb"``, an int or RGB floats 0-1."""
    if isinstance(color, str):
        return int(color.lstrip("#"), 16)
    if isinstance(color, int):
        return color
    r, g, b = (round(255 * c) for c in color[:3])
    return (r << 16) | (g << 8) | b


class Scene:
    """A MeshCat scene of one robot and its surroundings.

    Parameters
    ----------
    robot
        The robot to draw.
    zmq_url
        Attach to a running MeshCat server; by default a localhost-only server is started
        (and stopped at exit).
    """

    def __init__(self, robot: Robot, zmq_url: str | None = None) -> None:
        self.robot = robot
        self.server: LocalServer | None = None
        if zmq_url is None:
            self.server = start_server()
            zmq_url = self.server.zmq_url
        # meshcat prints its URL on connecting; the caller prints it once (Scene.url)
        with contextlib.redirect_stdout(io.StringIO()):
            self.viewer = meshcat.Visualizer(zmq_url=zmq_url)
        self.target = np.zeros(3)  # the world point at the middle of the view (m)
        self._drawn: list[np.ndarray] = []  # positions of props, markers and paths (m)
        self.visual, note = robot.geometry("visual")
        self.collision, _ = robot.geometry("collision")
        if note:
            print(f"wholebody: {note}", file=sys.stderr)
        self._pin = MeshcatVisualizer(robot.model, self.collision, self.visual)
        self._pin.initViewer(viewer=self.viewer)
        self._pin.loadViewerModel(rootNodeName="robot")
        self._visual_data = self.visual.createData()
        self._data = robot.model.createData()  # private: never touches the robot's data
        self.viewer["/Background"].set_property("top_color", [0.95, 0.96, 0.98])
        self.viewer["/Background"].set_property("bottom_color", [0.80, 0.83, 0.88])

    @property
    def url(self) -> str:
        """The page to open in a browser."""
        return self.viewer.url()

    # ------------------------------------------------------------------ camera
    def frame(self, points: np.ndarray | None = None, q: np.ndarray | None = None) -> None:
        """Aim the camera at ``points`` (N, 3) (m, world), the robot's links at ``q`` and
        every prop, marker and path drawn so far, all of them in view (:func:`camera_view`).

        The camera orbits the world origin (meshcat 0.3 cannot move its target), so the
        scene's roots (``/meshcat``, the grid and the axes) are shifted by minus the target;
        a mouse orbit then turns about the middle of the run."""
        parts = list(self._drawn)
        if points is not None:
            parts.append(np.asarray(points, dtype=float).reshape(-1, 3))
        if q is not None:
            parts.append(np.array([T[:3, 3] for _, T in self._placements(q)]))
        centre, offset = camera_view(np.vstack(parts) if parts else np.zeros((0, 3)))
        self.target = centre
        shift = _translation(-centre)
        # (meshcat's grid is turned into the floor by its object's own rotation, which a
        # transform of its node composes with: a translation keeps it on the floor)
        for root in ("/meshcat", "/Grid", "/Axes"):
            self.viewer[root].set_transform(shift)
        ox, oy, oz = offset  # the camera's node is y-up (three.js): world (x, y, z) -> (x, z, -y)
        self.viewer["/Cameras/default/rotated/<object>"].set_property(
            "position", [float(ox), float(oz), float(-oy)]
        )

    # ------------------------------------------------------------------ robot
    def show(self, q: np.ndarray) -> None:
        """Draw the robot at configuration ``q``."""
        self._pin.display(q)

    def _placements(self, q: np.ndarray) -> list[tuple[str, np.ndarray]]:
        pin.forwardKinematics(self.robot.model, self._data, q)
        pin.updateGeometryPlacements(self.robot.model, self._data, self.visual, self._visual_data)
        out = []
        for i, geom in enumerate(self.visual.geometryObjects):
            # as Pinocchio's visualizer does: the cylinders' axis swap is intrinsic to their
            # meshcat objects; placements carry the mesh scale
            T = self._visual_data.oMg[i].homogeneous
            T[:3, :3] *= geom.meshScale
            out.append((self._pin.getViewerNodeName(geom, pin.GeometryType.VISUAL), T))
        return out

    def animate(
        self,
        times: np.ndarray,
        qs: np.ndarray,
        fps: float = 30.0,
        extra: dict[str, np.ndarray] | None = None,
        frame: bool = True,
    ) -> None:
        """Replay a run (configurations ``qs`` at ``times`` s) as a MeshCat animation, resampled
        at ``fps``; ``extra`` maps scene paths to (N, 4, 4) poses animated alongside.
        ``frame``: aim the camera so that the whole replay stays in view (:meth:`frame`:
        every link at every frame, the animated props and everything drawn), instead of the
        start, which a robot driving metres away leaves."""
        anim = meshcat.animation.Animation(default_framerate=fps)
        frames = np.arange(0.0, float(times[-1]) + 1e-9, 1.0 / fps)
        index = np.searchsorted(times, frames).clip(0, len(times) - 1)
        seen = []
        for f, k in enumerate(index):
            with anim.at_frame(self.viewer, f) as node:
                for path, T in self._placements(qs[k]):
                    node[path].set_transform(T)
                    seen.append(T[:3, 3])
                for path, poses in (extra or {}).items():
                    node[path].set_transform(poses[k])
                    seen.append(poses[k][:3, 3])
        if frame:
            self.frame(np.array(seen))
        self.viewer.set_animation(anim, play=True, repetitions=1)

    def static_html(self) -> str:
        """The scene as one standalone HTML page (the viewer's script, the objects, the
        camera and the replay): it opens from a file, without a server."""
        return self.viewer.static_html()

    def save_html(self, path: str | Path) -> Path:
        """Write :meth:`static_html` to ``path`` atomically; returns ``path``."""
        return write_text(path, self.static_html())

    # ------------------------------------------------------------------ props
    def marker(
        self,
        name: str,
        position: Sequence[float],
        color: str | int = "#e4572e",
        radius: float = 0.02,
    ) -> None:
        """A small sphere (a target) at ``position`` (m, world)."""
        node = self.viewer["scene/markers"][name]
        node.set_object(mg.Sphere(radius), mg.MeshLambertMaterial(color=rgb(color)))
        node.set_transform(_translation(position))
        self._drawn.append(np.asarray(position, dtype=float).reshape(1, 3))

    def path(self, name: str, points: np.ndarray, color: str | int = "#17becf") -> None:
        """A polyline through ``points`` (N, 3) (a reference or executed trajectory)."""
        pts = np.asarray(points, dtype=np.float32).T
        self._drawn.append(pts.T.astype(float))
        self.viewer["scene/paths"][name].set_object(
            mg.Line(mg.PointsGeometry(pts), mg.LineBasicMaterial(color=rgb(color), linewidth=3))
        )

    def closest_pairs(self, pairs: Sequence, most: int = 3, safety: float = 0.01) -> None:
        """Lines between the witness points of the ``most`` closest of ``pairs``
        (:class:`~wholebody.collision.PairDistance`): red for a pair within 1 mm of
        ``safety`` (m) or closer, orange otherwise; earlier lines beyond them are removed."""
        near = sorted(pairs, key=lambda p: p.distance)[:most]
        node = self.viewer["scene/collision"]
        for i in range(most):
            if i >= len(near):
                node[f"pair_{i}"].delete()
                continue
            p = near[i]
            points = np.array([p.point_a, p.point_b], dtype=np.float32).T
            color = "#d62728" if p.distance <= safety + 1e-3 else "#ff7f0e"
            node[f"pair_{i}"].set_object(
                mg.Line(
                    mg.PointsGeometry(points), mg.LineBasicMaterial(color=rgb(color), linewidth=4)
                )
            )

    def box(
        self,
        name: str,
        size: Sequence[float],
        pose: np.ndarray,
        color: str | int = "#b08d57",
        opacity: float = 1.0,
    ) -> None:
        """A box of ``size`` (m) at the 4x4 ``pose`` (shelf, table, panel...)."""
        node = self.viewer["scene/props"][name]
        node.set_object(
            mg.Box(list(size)),
            _material(color, opacity),
        )
        self._prop(node, pose)

    def cylinder(
        self,
        name: str,
        radius: float,
        height: float,
        pose: np.ndarray,
        color: str | int = "#d62728",
        opacity: float = 0.8,
    ) -> None:
        """A cylinder (axis = the pose's z) of ``radius`` and ``height`` (m). MeshCat's
        cylinders run along y: the shape is a child node turned onto z, so the prop's own
        node takes poses (also in :meth:`animate`) like every other prop."""
        node = self.viewer["scene/props"][name]
        node["shape"].set_object(
            mg.Cylinder(height, radius),
            _material(color, opacity),
        )
        node["shape"].set_transform(_Y_TO_Z)
        self._prop(node, pose)

    def ellipsoid(
        self,
        name: str,
        radii: Sequence[float],
        pose: np.ndarray,
        color: str | int = "#d62728",
        opacity: float = 0.5,
    ) -> None:
        """An ellipsoid with semi-axes ``radii`` (m) at ``pose``."""
        node = self.viewer["scene/props"][name]
        node.set_object(
            mg.Ellipsoid(list(radii)),
            _material(color, opacity),
        )
        self._prop(node, pose)

    def _prop(self, node, pose: np.ndarray) -> None:
        """Place a prop's node at ``pose`` and remember where it is (for :meth:`frame`)."""
        pose = np.asarray(pose, dtype=float)
        node.set_transform(pose)
        self._drawn.append(pose[:3, 3].reshape(1, 3))

    def move(self, path: str, pose: np.ndarray) -> None:
        """Move an existing prop or marker, e.g. ``"scene/props/panel"``."""
        self.viewer[path].set_transform(np.asarray(pose, dtype=float))

    def clear(self) -> None:
        """Remove every prop, marker and path (the robot stays)."""
        self.viewer["scene"].delete()
        self._drawn.clear()

    def close(self) -> None:
        """Stop the server this scene started (if any)."""
        if self.server is not None:
            self.server.stop()


def _material(color: str | int, opacity: float) -> mg.MeshLambertMaterial:
    """A shaded material of ``color``, transparent below ``opacity`` 1."""
    return mg.MeshLambertMaterial(color=rgb(color), opacity=opacity, transparent=opacity < 1)


def _translation(p: Sequence[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T
