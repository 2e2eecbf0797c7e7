"""Live MeshCat visualisation on a localhost-only server: :class:`Scene` draws a robot from
its URDF geometry with targets, paths, obstacles and props, animates it live and replays a
whole run (:mod:`wholebody.viz.scene`, :mod:`wholebody.viz.server`); :func:`replay` shows
a run in one call (:mod:`wholebody.viz.replay`)."""

from wholebody.viz.replay import replay
from wholebody.viz.scene import Scene, rgb
from wholebody.viz.server import LocalServer, start_server

__all__ = ["LocalServer", "Scene", "replay", "rgb", "start_server"]
