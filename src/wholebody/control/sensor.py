"""What a controller measures of its plant: joint positions with noise, late.

A real controller reads encoders, whose positions carry noise and reach it after a delay.
:class:`JointSensor` puts both on a plant's state read (``MujocoPlant(..., sensor=)``,
``run_scenario(..., sensor=)``, ``wholebody run --sensor-noise A --sensor-delay N``): the
controller's step ``k`` sees

    q_seen(k) = integrate(q(k - delay), n(k), 1 s),     n(k) ~ U[-noise, noise]^nu

where ``q(j)`` is the simulated configuration at the start of control period ``j`` (``q(0)``
for ``j < 0``: the robot at rest before the run) and ``n`` is one draw per actuated
coordinate, that is per encoder, integrated as a velocity held for one second
(:meth:`Robot.integrate`, exact on the manifold): a joint's angle (rad; a continuous
joint's too) or a prismatic joint's position (m) is off by at most ``noise``, a wheel's
angle too (the base then stands where that wheel turn would put it, ``B n``), a planar base
without wheels has its x, y (m, its own axes) and yaw (rad) off by at most ``noise``, and a
mimic joint follows its leader. The draws are independent per coordinate and period, from
``numpy.random.default_rng(seed)`` started again at every reset: a run is repeatable. The
controller's first step sees the start configuration exactly (it is given, not measured).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from wholebody.errors import ConfigError
from wholebody.robot import Robot

__all__ = ["JointSensor", "SensorReadout"]


@dataclass(frozen=True)
class JointSensor:
    """The measurement model (module docstring): ``noise`` (rad or m, the half-width of the
    uniform draw; 0 for none), ``delay`` (control periods, a whole number >= 0) and the draws'
    ``seed``. The default is exact: the plant's state as it is."""

    noise: float = 0.0
    delay: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        noise = self.noise
        if (
            isinstance(noise, bool)
            or not isinstance(noise, int | float)
            or not math.isfinite(noise)
            or noise < 0
        ):
            raise ConfigError(
                f"sensor noise must be a finite number >= 0 (rad or m), got {noise!r}"
            )
        for name in ("delay", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                what = "control periods" if name == "delay" else "the noise's seed"
                raise ConfigError(
                    f"sensor {name} must be a whole number >= 0 ({what}), got {value!r}"
                )

    @property
    def exact(self) -> bool:
        """Whether the controller sees the plant's state as it is (no noise, no delay)."""
        return self.noise == 0 and self.delay == 0

    def start(self, robot: Robot, q0: np.ndarray) -> SensorReadout:
        """A readout of ``robot``'s configurations from ``q0``, at rest before it."""
        return SensorReadout(self, robot, q0)

    def describe(self) -> dict[str, float | int]:
        """The model as plain data (a run's metrics)."""
        return {"noise_rad_or_m": self.noise, "delay_periods": self.delay, "seed": self.seed}


class SensorReadout:
    """The running state of a :class:`JointSensor`: the configurations of the last ``delay``
    periods and the noise's generator."""

    def __init__(self, sensor: JointSensor, robot: Robot, q0: np.ndarray) -> None:
        self.sensor = sensor
        self._robot = robot
        self._rng = np.random.default_rng(sensor.seed)
        q0 = np.array(q0, dtype=float)
        self._history: deque[np.ndarray] = deque([q0] * (sensor.delay + 1), maxlen=sensor.delay + 1)

    def read(self, q: np.ndarray) -> np.ndarray:
        """What the controller sees now that the plant is at ``q`` (a new array): the
        configuration of ``delay`` reads ago, perturbed by the noise."""
        self._history.append(np.array(q, dtype=float))
        seen = self._history[0]
        if self.sensor.noise == 0:
            return seen.copy()
        a = self.sensor.noise
        return self._robot.integrate(seen, self._rng.uniform(-a, a, self._robot.nu), 1.0)
