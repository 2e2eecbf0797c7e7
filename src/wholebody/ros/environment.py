"""Where a node looks for peers, and what to install when ROS 2 is missing.

ROS 2 (Jazzy and later) discovers peers within ``ROS_AUTOMATIC_DISCOVERY_RANGE``; our
commands set it to ``LOCALHOST`` unless the user has set it, so a node started next to a
robot talks to this host only until the user opens it to the network (``SUBNET``, or
``ROS_STATIC_PEERS``), in the way ROS 2's own default is meant to be narrowed.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

from wholebody.errors import ConfigError

__all__ = ["INSTALL", "require_rclpy", "ros_environment"]

INSTALL = "pip install 'wholebody[ros]'"
"""The command that installs the ROS 2 client library and messages (the ``ros`` extra)."""

DISCOVERY = "ROS_AUTOMATIC_DISCOVERY_RANGE"


def ros_environment(env: MutableMapping[str, str] | None = None) -> MutableMapping[str, str]:
    """``env`` (default ``os.environ``) with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
    unless it is set already (then it is left as the user set it)."""
    env = os.environ if env is None else env
    env.setdefault(DISCOVERY, "LOCALHOST")
    return env


def require_rclpy() -> None:
    """Import ``rclpy`` and the messages the nodes use, or a :class:`ConfigError` saying
    what to install."""
    try:
        import diagnostic_msgs.msg  # noqa: F401
        import geometry_msgs.msg  # noqa: F401
        import nav_msgs.msg  # noqa: F401
        import rclpy  # noqa: F401
        import sensor_msgs.msg  # noqa: F401
        import std_msgs.msg  # noqa: F401
        import visualization_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise ConfigError(
            f"the ROS 2 commands need rclpy and the standard messages: {INSTALL} "
            f"(from a checkout: pip install '.[ros]'); {exc}"
        ) from None
