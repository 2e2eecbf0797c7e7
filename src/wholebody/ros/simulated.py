"""A robot without a robot: what ``wholebody ros-sim`` integrates (no ROS here).

Each period the simulated robot applies the newest velocity command for the period and
returns the configuration reached: exactly (``kinematic``: :meth:`Robot.integrate`) or under
physics (``mujoco``: :class:`wholebody.sim.MujocoPlant`, its joint servos with the robot's
torque limits). Commands arrive by name (``/wholebody/command``: any joints, in any order;
the others at zero) or as an array in ``robot.toml``'s order
(``/wholebody/velocity_commands``, :func:`~wholebody.ros.interface.velocity_order`); the
newest of either is applied.

Like a drive, the robot stops (applies zero) when no command arrived for
``command_timeout`` seconds, and refuses a command that is not finite or has the wrong
length (then also applying zero).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from wholebody.errors import ConfigError
from wholebody.robot import Robot
from wholebody.ros.interface import velocity_permutation

__all__ = ["SIMS", "SimulatedRobot"]

SIMS = ("kinematic", "mujoco")


class SimulatedRobot:
    """A robot integrated from velocity commands (module docstring).

    Parameters
    ----------
    robot
        The robot.
    sim
        ``"kinematic"`` or ``"mujoco"`` (the ``sim`` extra).
    dt
        The period (s); under MuJoCo a whole number of its physics steps.
    q0
        The start configuration (default the robot's home posture).
    command_timeout
        Seconds without a command after which the robot stops.
    """

    def __init__(
        self,
        robot: Robot,
        sim: str,
        dt: float,
        q0: np.ndarray | None = None,
        command_timeout: float = 0.1,
    ) -> None:
        if sim not in SIMS:
            raise ConfigError(f"unknown sim {sim!r}: expected one of {', '.join(SIMS)}")
        self.robot, self.sim, self.dt = robot, sim, float(dt)
        self.q = robot.check_configuration(robot.home() if q0 is None else q0).copy()
        self.u = np.zeros(robot.nu)
        self.last_applied = np.zeros(robot.nu)
        """The command applied in the last period (rad/s, m/s)."""
        self.timeout = float(command_timeout)
        self._received = -math.inf
        self._order = velocity_permutation(robot)
        self._index = {n: k for k, n in enumerate(robot.actuated_joints)}
        self.plant = None
        self._steps = 0
        if sim == "mujoco":
            try:
                from wholebody.sim import MujocoPlant
            except ImportError as exc:
                raise ConfigError(
                    f"--sim mujoco needs MuJoCo: pip install 'wholebody[sim]' ({exc})"
                ) from None
            self.plant = MujocoPlant(robot, settings=robot.sim_settings)
            self.plant.reset(self.q)

    def on_command(
        self, names: Sequence[str], velocities: Sequence[float], now: float
    ) -> str | None:
        """A command by joint name received at ``now`` (s): None when taken, else why it
        was refused (the robot then stops)."""
        if len(names) != len(velocities):
            return self._refuse(f"{len(names)} names but {len(velocities)} velocities", now)
        u = np.zeros(self.robot.nu)
        for name, v in zip(names, velocities, strict=True):
            k = self._index.get(name)
            if k is not None:
                u[k] = v
        return self._take(u, now)

    def on_array(self, values: Sequence[float], now: float) -> str | None:
        """A command in ``robot.toml``'s joint order received at ``now``: None or why it
        was refused."""
        if len(values) != self.robot.nu:
            return self._refuse(f"{len(values)} velocities, expected {self.robot.nu}", now)
        u = np.zeros(self.robot.nu)
        u[self._order] = values
        return self._take(u, now)

    def _take(self, u: np.ndarray, now: float) -> str | None:
        if not np.all(np.isfinite(u)):
            return self._refuse("not finite", now)
        self.u, self._received = u, now
        return None

    def _refuse(self, why: str, now: float) -> str:
        self.u, self._received = np.zeros(self.robot.nu), now
        return f"command refused: {why}"

    def applied(self, now: float) -> np.ndarray:
        """The command applied in the period starting at ``now``: the newest, or zero
        after ``command_timeout`` without one."""
        return self.u if now - self._received <= self.timeout else np.zeros(self.robot.nu)

    def step(self, now: float) -> np.ndarray:
        """One period from ``now``: the configuration reached."""
        u = self.applied(now)
        if self.plant is None:
            self.q = self.robot.integrate(self.q, u, self.dt)
        else:
            self.q = self.plant.step(self.q, u, self.dt)
            self._steps += 1
            if self._steps % 1000 == 0:  # the plant's per-period records: not kept here
                from wholebody.sim import PhysicsLog

                self.plant.log = PhysicsLog()
        self.last_applied = u
        return self.q

    @property
    def stop_reason(self) -> str | None:
        """Why the physics stopped (a joint stalled at its torque limit, a divergence)."""
        return None if self.plant is None else self.plant.stop_reason
