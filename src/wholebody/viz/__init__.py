"""Live MeshCat visualisation on a localhost-only server: :class:`Scene` draws a robot from
its URDF geometry with targets, paths, obstacles and props, animates it live and replays a
whole run (:mod:`wholebody.viz.scene`, :mod:`wholebody.viz.server`)."""

from wholebody.viz.scene import Scene, rgb
from wholebody.viz.server import LocalServer, start_server

__all__ = ["LocalServer", "Scene", "rgb", "start_server"]
