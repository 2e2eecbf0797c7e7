"""The arm angle people choose: ``alpha_h(p)`` of the normalised wrist, with its gradient.

A person's arm has one degree of redundancy for a given wrist position: the arm angle
``alpha`` (:mod:`wholebody.arm.angle`: the elbow's rotation about the shoulder-wrist line,
0 with the elbow at its lowest, > 0 outwards, mirrored arms equal). A
:class:`HumanArmAngleModel` gives the arm angle people hold, learned from recordings
(:mod:`wholebody.humanlike.arm_angle_fit`), as a function of the **normalised wrist**::

    p = (W - S) / (L1 + L2)          (dimensionless, |p| <= 1)

``W - S`` the wrist relative to the shoulder in the arm's canonical axes (x forward, y
medial, z up: :mod:`wholebody.arm.stiffness`; left arms mirrored) and ``L1 + L2`` the
arm's length (upper arm + forearm, shoulder-elbow and elbow-wrist distances). Dividing by
the length makes the input the same for a person and a robot of other proportions: the
robot queries the model with its own ``W - S``, ``L1`` and ``L2``
(:func:`normalised_wrist`), and chains the gradient as
``d alpha_h / d(W - S) = (d alpha_h / dp) / (L1 + L2)``.

Every model returns ``alpha_h`` (rad) and ``d alpha_h / dp`` (3,) (rad per unit of ``p``),
and states its ``spread`` (rad): the standard deviation of people's arm angles about the
model, between and within persons, measured on people the model did not see. A
controller that pulls the elbow towards ``alpha_h`` should not pull harder than that
spread warrants.

The network
-----------
:class:`NetworkArmAngle` is the tanh perceptron of :mod:`wholebody.arm.mlp` with a linear
output (no floor: an arm angle has either sign)::

    alpha_h = alpha_mean + alpha_scale (w_out . h_L + b_out)
    d alpha_h/dp = alpha_scale w_out^T D_L W_L ... D_1 W_1 / x_scale

Outside the recorded workspace (its box ``input_low``/``input_high`` is stored) the tanh
units saturate: ``alpha_h`` levels off to a bounded value and its gradient vanishes.

File (``.npz``, no pickled objects)
-----------------------------------
``format`` ("wholebody.arm_angle_mlp/1"), ``n_layers``, ``W0``, ``b0``, ... (as the stiffness
network's), ``activation`` ("tanh"), ``x_mean``, ``x_scale`` (3,) (dimensionless),
``alpha_mean``, ``alpha_scale`` (rad), ``spread``, ``spread_between``, ``spread_within``
(rad), ``input_low``, ``input_high`` (3,) and ``meta`` (0-d JSON string: data, training
settings, cross-validated scores, date). :func:`default_arm_angle_model` loads the shipped
``data/arm_angle/human_arm_angle.npz`` (its data card is the README beside it).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wholebody.arm import mlp
from wholebody.errors import DataError, DimensionError
from wholebody.resources import data_dir

__all__ = [
    "FORMAT",
    "ConstantArmAngle",
    "HumanArmAngleModel",
    "NetworkArmAngle",
    "arm_angle_model_path",
    "default_arm_angle_model",
    "normalised_wrist",
]

FORMAT = "wholebody.arm_angle_mlp/1"


def normalised_wrist(wrist: np.ndarray, upper_arm: float, forearm: float) -> np.ndarray:
    """``p = (W - S) / (L1 + L2)``: the model input for a wrist ``W - S`` (..., 3) (m, canonical
    arm axes) and an arm of upper arm ``L1`` and forearm ``L2`` (m). Why: one model serves
    arms of any size."""
    reach = float(upper_arm) + float(forearm)
    if not (math.isfinite(reach) and upper_arm > 0 and forearm > 0):
        raise DimensionError(
            f"normalised_wrist: the arm's lengths must be > 0 m, got {upper_arm} and {forearm}"
        )
    return np.asarray(wrist, dtype=float) / reach


class HumanArmAngleModel(ABC):
    """``alpha_h(p)`` with its gradient and the ``spread`` of people about it (module
    docstring). ``spread`` is in rad."""

    spread: float

    @abstractmethod
    def evaluate(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """Arm angle (rad) and ``d alpha_h / dp`` (3,) at one normalised wrist ``p`` (3,)."""

    def predict(self, P: np.ndarray) -> np.ndarray:
        """Arm angles (rad) at normalised wrists (..., 3); a loop over :meth:`evaluate`
        unless a model has a vectorised one."""
        P = np.asarray(P, dtype=float)
        flat = P.reshape(-1, 3)
        return np.array([self.evaluate(p)[0] for p in flat]).reshape(P.shape[:-1])


def _checked_point(p: np.ndarray, who: str) -> np.ndarray:
    a = np.asarray(p, dtype=float)
    if a.shape != (3,):
        raise DimensionError(f"{who}: the normalised wrist is a (3,) array, got shape {a.shape}")
    return a


def _spread(value: object, name: str, who: str) -> float:
    s = mlp.number(value, name, who)
    if not (math.isfinite(s) and s >= 0):
        raise DimensionError(f"{who}: {name} must be a finite angle >= 0 rad, got {s}")
    return s


class ConstantArmAngle(HumanArmAngleModel):
    """One arm angle everywhere (the baseline: people's mean), with its spread (rad)."""

    def __init__(self, alpha: float, spread: float) -> None:
        self.alpha = mlp.number(alpha, "alpha", "ConstantArmAngle")
        if not math.isfinite(self.alpha):
            raise DimensionError(f"ConstantArmAngle: alpha must be finite, got {self.alpha}")
        self.spread = _spread(spread, "spread", "ConstantArmAngle")
        self._zero = np.zeros(3)
        self._zero.setflags(write=False)

    def evaluate(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        _checked_point(p, "ConstantArmAngle")
        return self.alpha, self._zero

    def predict(self, P: np.ndarray) -> np.ndarray:
        return np.full(np.shape(P)[:-1], self.alpha)

    def __repr__(self) -> str:
        return (
            f"ConstantArmAngle({math.degrees(self.alpha):.1f} deg, spread "
            f"{math.degrees(self.spread):.1f} deg)"
        )


class NetworkArmAngle(mlp.TanhNetwork, HumanArmAngleModel):
    """The learned arm-angle network (module docstring).

    Parameters
    ----------
    weights, biases
        Per layer, hidden layers first, then the output layer (1 row).
    x_mean, x_scale
        Input normalisation (dimensionless, like ``p``).
    alpha_mean, alpha_scale
        Output de-normalisation (rad).
    spread, spread_between, spread_within
        sd of people about the model (rad): in all, between persons (rms of each person's
        mean deviation) and within persons (rms about that mean);
        ``spread^2 = spread_between^2 + spread_within^2``. The two parts default to 0.
    input_low, input_high
        Bounding box of the training inputs, for :meth:`in_range`.
    meta
        Provenance (JSON-serialisable).
    """

    def __init__(
        self,
        weights: Sequence[np.ndarray],
        biases: Sequence[np.ndarray],
        x_mean: np.ndarray,
        x_scale: np.ndarray,
        alpha_mean: float,
        alpha_scale: float,
        spread: float,
        *,
        spread_between: float = 0.0,
        spread_within: float = 0.0,
        input_low: np.ndarray | None = None,
        input_high: np.ndarray | None = None,
        meta: dict | None = None,
    ) -> None:
        who = "NetworkArmAngle"
        self.weights, self.biases = mlp.check_layers(weights, biases, who)
        self.x_mean = mlp.vector3(x_mean, "x_mean", who)
        self.x_scale = mlp.vector3(x_scale, "x_scale", who)
        self.alpha_mean = mlp.number(alpha_mean, "alpha_mean", who)
        self.alpha_scale = mlp.number(alpha_scale, "alpha_scale", who)
        if not (np.all(self.x_scale > 0) and self.alpha_scale > 0):
            raise DimensionError(f"{who}: x_scale and alpha_scale must be > 0")
        self.spread = _spread(spread, "spread", who)
        self.spread_between = _spread(spread_between, "spread_between", who)
        self.spread_within = _spread(spread_within, "spread_within", who)
        box = [
            None if v is None else mlp.vector3(v, n, who)
            for v, n in ((input_low, "input_low"), (input_high, "input_high"))
        ]
        self.input_low, self.input_high = box
        numbers = [
            *self.weights,
            *self.biases,
            self.x_mean,
            self.x_scale,
            np.array([self.alpha_mean, self.alpha_scale]),
        ]
        numbers += [v for v in box if v is not None]
        if not all(np.isfinite(a).all() for a in numbers):
            raise DimensionError(f"{who}: weights, biases and normalisations must be finite")
        self.meta = dict(meta or {})
        self._layers, self._w_out, self._b_out = mlp.fold(
            self.weights,
            self.biases,
            self.x_mean,
            self.x_scale,
            self.alpha_mean,
            self.alpha_scale,
        )
        self._wT = [W.T.copy() for W, _ in self._layers]

    # ----------------------------------------------------------------- inference
    def predict(self, P: np.ndarray) -> np.ndarray:
        """Arm angles (rad) at normalised wrists (..., 3), vectorised."""
        return mlp.forward(self._layers, P)[-1] @ self._w_out + self._b_out

    def gradient(self, P: np.ndarray) -> np.ndarray:
        """``d alpha_h / dp`` (..., 3) (rad per unit of p), vectorised."""
        hs = mlp.forward(self._layers, P)
        return mlp.backward_batch(self._layers, hs, self._w_out)

    def evaluate(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """``alpha_h`` (rad) and ``d alpha_h / dp`` (3,) at one normalised wrist (3,)."""
        hs = mlp.forward_states(self._layers, _checked_point(p, "NetworkArmAngle"))
        alpha = float(self._w_out @ hs[-1]) + self._b_out
        return alpha, mlp.backward(self._wT, hs, self._w_out)

    def __repr__(self) -> str:
        return (
            f"NetworkArmAngle(hidden={self.hidden_sizes}, tanh, spread "
            f"{math.degrees(self.spread):.1f} deg)"
        )

    # ----------------------------------------------------------------- file
    def save(self, path: str | Path) -> Path:
        """Write the network (module docstring layout); returns the file written (``.npz``
        appended to a name without it)."""
        numbers = ("alpha_mean", "alpha_scale", "spread", "spread_between", "spread_within")
        return self.write(path, FORMAT, numbers)

    @classmethod
    def load(cls, path: str | Path) -> NetworkArmAngle:
        """Read a network file.

        Raises
        ------
        DataError
            Not an arm-angle network file, a missing key, inconsistent shapes or non-finite
            numbers (named, with the file).
        """
        return mlp.read_network(path, "arm-angle network", cls._read)

    @classmethod
    def _read(cls, path: Path, z: dict[str, np.ndarray]) -> NetworkArmAngle:
        """The network in an open file (:meth:`load`)."""
        need = (
            "format",
            "n_layers",
            "activation",
            "x_mean",
            "x_scale",
            "alpha_mean",
            "alpha_scale",
            "spread",
        )
        mlp.check_header(path, z, need, FORMAT)
        weights, biases = mlp.read_layers(path, z)
        try:
            return cls(
                weights,
                biases,
                z["x_mean"],
                z["x_scale"],
                z["alpha_mean"],
                z["alpha_scale"],
                z["spread"],
                spread_between=z.get("spread_between", 0.0),
                spread_within=z.get("spread_within", 0.0),
                input_low=z.get("input_low"),
                input_high=z.get("input_high"),
                meta=mlp.read_meta(path, z),
            )
        except DimensionError as exc:
            raise DataError(f"{path}: {exc}") from None


def arm_angle_model_path() -> Path:
    """Where the shipped arm-angle network lives: ``data/arm_angle/human_arm_angle.npz``."""
    return data_dir() / "arm_angle" / "human_arm_angle.npz"


def default_arm_angle_model() -> NetworkArmAngle:
    """The shipped network of people's arm angle (its data card: the README beside it)."""
    path = arm_angle_model_path()
    if not path.is_file():
        raise DataError(
            f"{path}: no arm-angle network there; train one with `wholebody "
            f"stiffness armangle fit --out {path}`"
        )
    return NetworkArmAngle.load(path)
