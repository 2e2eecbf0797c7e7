"""A ROS 2 node for the controller (``wholebody ros``) and a simulated robot to try it
(``wholebody ros-sim``).

The ROS interface (topics, messages, units) is the README's "On a robot (ROS 2)" section.
Only :mod:`~wholebody.ros.node`, :mod:`~wholebody.ros.sim_node` and
:mod:`~wholebody.ros.messages` import ``rclpy`` (the ``ros`` extra); the logic they run is
plain Python, tested without ROS:

* :mod:`~wholebody.ros.joint_state` -- measured joint positions and base pose to ``q``,
  each input checked, and how old the newest complete state is;
* :mod:`~wholebody.ros.safety` -- the command limiter (velocity and acceleration limits)
  and the checks of targets and feed-forward twists;
* :mod:`~wholebody.ros.core` -- one control period: state, targets, stack, limiter, and
  what the node does on each fault;
* :mod:`~wholebody.ros.stacks` -- the stack a node runs (default or a scenario's);
* :mod:`~wholebody.ros.timing` -- the period clock and its statistics;
* :mod:`~wholebody.ros.environment` -- ROS discovery kept on this host by default, and the
  message for a missing extra.
"""

from __future__ import annotations
