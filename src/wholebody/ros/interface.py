"""The node's ROS interface as data: topic names, the command's joint order, and the
``forward_command_controller`` configuration that takes it (no ROS here).

``/wholebody/velocity_commands`` lists the velocities in the order ``robot.toml`` names the
joints: the base's actuators (``[base] wheels``), then each ``[groups]`` entry's joints in
order, without repeats; actuated joints no group names follow in ``u``'s order. That is the
order a ``joints:`` list in a controller's YAML is written in, and it is not ``u``'s (which
follows the URDF's tree: TIAGo++'s head comes after its arms there).
"""

from __future__ import annotations

import numpy as np

from wholebody.robot import Robot

__all__ = [
    "COMMAND",
    "MARKERS",
    "STATUS",
    "VELOCITY_COMMANDS",
    "controller_yaml",
    "frame_topic",
    "velocity_order",
]

COMMAND = "/wholebody/command"
VELOCITY_COMMANDS = "/wholebody/velocity_commands"
STATUS = "/wholebody/status"
MARKERS = "/wholebody/markers"
JOINT_STATES = "/joint_states"
ODOM = "/odom"
CMD_VEL = "/cmd_vel"
CONTROLLER = "wholebody_velocity_controller"
"""The name the README's controller configuration gives the forward command controller."""


def frame_topic(frame: str, what: str) -> str:
    """``/wholebody/<frame>/<what>`` (``target``, ``twist``, ``pose``)."""
    return f"/wholebody/{frame}/{what}"


def velocity_order(robot: Robot) -> list[str]:
    """The joints of ``/wholebody/velocity_commands``, in ``robot.toml``'s order (module
    docstring)."""
    actuated = set(robot.actuated_joints)
    order: list[str] = []
    listed = [*robot.base.actuators, *(j for g in robot.config.groups.values() for j in g)]
    for name in [*listed, *robot.actuated_joints]:
        if name in actuated and name not in order:
            order.append(name)
    return order


def velocity_permutation(robot: Robot) -> np.ndarray:
    """``p`` with ``u[p]`` the velocities in :func:`velocity_order`."""
    return np.array([robot.index(n) for n in velocity_order(robot)], dtype=int)


def controller_yaml(robot: Robot, rate_hz: float = 100.0) -> str:
    """A ros2_control configuration: a ``forward_command_controller`` taking velocities of
    :func:`velocity_order`'s joints on ``/wholebody/velocity_commands`` (remap its
    ``~/commands``, see the README)."""
    joints = "\n".join(f"      - {n}" for n in velocity_order(robot))
    return (
        f"controller_manager:\n"
        f"  ros__parameters:\n"
        f"    update_rate: {rate_hz:g}\n"
        f"    {CONTROLLER}:\n"
        f"      type: forward_command_controller/ForwardCommandController\n"
        f"\n"
        f"{CONTROLLER}:\n"
        f"  ros__parameters:\n"
        f"    interface_name: velocity\n"
        f"    joints:\n"
        f"{joints}\n"
    )
