"""Physics in the loop: a robot and a scenario's objects in MuJoCo (the ``sim`` extra).

:func:`build_world` compiles the MuJoCo model from the controller's own robot model and the
objects; :class:`MujocoPlant` steps it under a controller's velocity commands through joint
servos and reads the simulated state back, exactly or through a
:class:`~wholebody.control.JointSensor` (encoder noise, a measurement delay).
``wholebody run SCENARIO --sim mujoco`` runs a scenario this way
(:func:`wholebody.scenarios.run_scenario` with ``sim="mujoco"``).
"""

from wholebody.robot.sim import SimSettings
from wholebody.sim.plant import MujocoPlant, PhysicsLog
from wholebody.sim.world import World, build_world

__all__ = ["MujocoPlant", "PhysicsLog", "SimSettings", "World", "build_world"]
