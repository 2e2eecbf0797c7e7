"""MeshCat scenes: the robot from its URDF geometry, targets, paths, obstacles and props.

The viewer runs on a localhost-only server (:mod:`wholebody.viz.server`). The robot is drawn
by Pinocchio's MeshCat visualizer from the URDF's visual geometry; everything else is
meshcat primitives under ``/scene``. A run can be shown live (:meth:`Scene.show`, called
from the control loop) and replayed afterwards as a MeshCat animation
(:meth:`Scene.animate`), which the page plays with its own controls.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import meshcat
import meshcat.animation
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from pinocchio.visualize import MeshcatVisualizer

from wholebody.robot import Robot
from wholebody.viz.server import LocalServer, start_server

__all__ = ["Scene", "rgb"]

_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])


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
        self.viewer = meshcat.Visualizer(zmq_url=zmq_url)
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
    ) -> None:
        """Replay a run (configurations ``qs`` at ``times`` s) as a MeshCat animation, resampled
        at ``fps``; ``extra`` maps scene paths to (N, 4, 4) poses animated alongside."""
        anim = meshcat.animation.Animation(default_framerate=fps)
        frames = np.arange(0.0, float(times[-1]) + 1e-9, 1.0 / fps)
        index = np.searchsorted(times, frames).clip(0, len(times) - 1)
        for f, k in enumerate(index):
            with anim.at_frame(self.viewer, f) as frame:
                for path, T in self._placements(qs[k]):
                    frame[path].set_transform(T)
                for path, poses in (extra or {}).items():
                    frame[path].set_transform(poses[k])
        self.viewer.set_animation(anim, play=True, repetitions=1)

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

    def path(self, name: str, points: np.ndarray, color: str | int = "#17becf") -> None:
        """A polyline through ``points`` (N, 3) (a reference or executed trajectory)."""
        pts = np.asarray(points, dtype=np.float32).T
        self.viewer["scene/paths"][name].set_object(
            mg.Line(mg.PointsGeometry(pts), mg.LineBasicMaterial(color=rgb(color), linewidth=3))
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
        node.set_transform(np.asarray(pose, dtype=float))

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
        node.set_transform(np.asarray(pose, dtype=float))

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
        node.set_transform(np.asarray(pose, dtype=float))

    def move(self, path: str, pose: np.ndarray) -> None:
        """Move an existing prop or marker, e.g. ``"scene/props/panel"``."""
        self.viewer[path].set_transform(np.asarray(pose, dtype=float))

    def clear(self) -> None:
        """Remove every prop, marker and path (the robot stays)."""
        self.viewer["scene"].delete()

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
