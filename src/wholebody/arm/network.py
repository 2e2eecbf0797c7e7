"""The stiffness network in numpy: ``k(wrist)`` and its analytic gradient, and its file.

The network (Niu et al. 2024, Figure 6a: fully connected, wrist (x, y, z) in, k out) is a
multilayer perceptron with tanh hidden layers (smooth, so the gradient the controller uses
has no kinks), trained in PyTorch (:mod:`wholebody.humanlike.training`) and evaluated here
with plain numpy (no torch at run time)::

    z   = (p - x_mean) / x_scale                     p: canonical wrist (m), see stiffness.py
    h_1 = tanh(W_1 z + b_1),  h_i = tanh(W_i h_{i-1} + b_i)
    r   = k_mean + k_scale (w_out . h_L + b_out)     (N m/rad)
    k   = softplus_beta(r) = log(1 + exp(beta r)) / beta

The last step is a smooth floor: a stiffness is never negative, and ``k = r`` to within
``log(2)/beta`` where ``r`` is well above zero (``beta`` is stored in the file; 1/beta is
1 % of ``k_scale``). The gradient is exact for the value returned::

    dk/dp = sigmoid(beta r) k_scale  w_out^T D_L W_L ... D_1 W_1 / x_scale,  D_i = diag(1 - h_i^2)

Outside the training data (its bounding box is stored as ``input_low``/``input_high``) the
tanh units saturate, so ``k`` levels off to a bounded value with a vanishing gradient
instead of growing; the floor keeps it >= 0. :meth:`NetworkStiffness.in_range` says whether
a point lies in the box.

File (``.npz``, no pickled objects)
-----------------------------------
``format`` ("wholebody.stiffness_mlp/1"), ``n_layers`` (hidden layers + 1), ``W0``, ``b0``, ...
(``W_i`` of shape (out, in); the last is the output layer (1, H)), ``activation``
("tanh"), ``x_mean``, ``x_scale`` (3,) m, ``k_mean``, ``k_scale`` N m/rad, ``floor_beta``
rad/(N m), ``input_low``, ``input_high`` (3,) m and ``meta`` (0-d JSON string: robot, data,
split, training settings, scores, date).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wholebody.arm import mlp
from wholebody.arm.stiffness import StiffnessModel
from wholebody.errors import DataError, DimensionError
from wholebody.resources import robots_dir

__all__ = ["FORMAT", "NetworkStiffness", "default_stiffness"]

FORMAT = "wholebody.stiffness_mlp/1"


class NetworkStiffness(mlp.TanhNetwork, StiffnessModel):
    """The trained stiffness network as a :class:`StiffnessModel` (module docstring).

    Parameters
    ----------
    weights, biases
        Per layer, hidden layers first, then the output layer (1 row).
    x_mean, x_scale
        Input normalisation (m).
    k_mean, k_scale
        Output de-normalisation (N m/rad).
    floor_beta
        Sharpness of the smooth floor (rad/(N m)).
    input_low, input_high
        Bounding box of the training inputs (m), for :meth:`in_range`.
    meta
        Provenance (free-form, JSON-serialisable).
    """

    def __init__(
        self,
        weights: Sequence[np.ndarray],
        biases: Sequence[np.ndarray],
        x_mean: np.ndarray,
        x_scale: np.ndarray,
        k_mean: float,
        k_scale: float,
        floor_beta: float,
        input_low: np.ndarray | None = None,
        input_high: np.ndarray | None = None,
        meta: dict | None = None,
    ) -> None:
        who = "NetworkStiffness"
        self.weights, self.biases = mlp.check_layers(weights, biases, who)
        self.x_mean = mlp.vector3(x_mean, "x_mean", who)
        self.x_scale = mlp.vector3(x_scale, "x_scale", who)
        self.k_mean = mlp.number(k_mean, "k_mean", who)
        self.k_scale = mlp.number(k_scale, "k_scale", who)
        self.floor_beta = mlp.number(floor_beta, "floor_beta", who)
        if not (np.all(self.x_scale > 0) and self.k_scale > 0 and self.floor_beta > 0):
            raise DimensionError("NetworkStiffness: x_scale, k_scale and floor_beta must be > 0")
        self.input_low = None if input_low is None else mlp.vector3(input_low, "input_low", who)
        self.input_high = None if input_high is None else mlp.vector3(input_high, "input_high", who)
        numbers = [
            *self.weights,
            *self.biases,
            self.x_mean,
            self.x_scale,
            np.array([self.k_mean, self.k_scale, self.floor_beta]),
        ]
        numbers += [v for v in (self.input_low, self.input_high) if v is not None]
        if not all(np.isfinite(a).all() for a in numbers):
            raise DimensionError(
                "NetworkStiffness: weights, biases and normalisations must be "
                "finite (a NaN here makes every control step fail)"
            )
        self.meta = dict(meta or {})
        # the normalisations folded into the first and last layers for the control loop
        self._layers, self._w_out, self._b_out = mlp.fold(
            self.weights, self.biases, self.x_mean, self.x_scale, self.k_mean, self.k_scale
        )
        self._wT = [W.T.copy() for W, _ in self._layers]

    # ----------------------------------------------------------------- inference
    def raw(self, P: np.ndarray) -> np.ndarray:
        """The network output before the floor, ``r`` (N m/rad), for points (..., 3)."""
        return mlp.forward(self._layers, P)[-1] @ self._w_out + self._b_out

    def predict(self, P: np.ndarray) -> np.ndarray:
        """Stiffness (N m/rad) at canonical wrist positions (..., 3) (m), vectorised."""
        r = self.raw(P) * self.floor_beta
        return (np.maximum(r, 0.0) + np.log1p(np.exp(-np.abs(r)))) / self.floor_beta

    def gradient(self, P: np.ndarray) -> np.ndarray:
        """``dk/dp`` (..., 3) (N m/rad per m), vectorised."""
        hs = mlp.forward(self._layers, P)
        r = hs[-1] @ self._w_out + self._b_out
        g = (0.5 * (1.0 + np.tanh(0.5 * self.floor_beta * r)))[..., None] * self._w_out
        return mlp.backward_batch(self._layers, hs, g)

    def evaluate(self, wrist: np.ndarray) -> tuple[float, np.ndarray]:
        """``k`` (N m/rad) and ``dk/dwrist`` (3,) at one canonical wrist position (m).

        Plain numpy on preloaded arrays (a few microseconds): it runs twice per control step.
        """
        h = np.asarray(wrist, dtype=float)
        if h.shape != (3,):
            raise DimensionError(
                f"stiffness network: the wrist position is a (3,) array (m), got shape {h.shape}"
            )
        hs = mlp.forward_states(self._layers, h)
        r = float(self._w_out @ hs[-1]) + self._b_out
        br = self.floor_beta * r
        if br > 30.0:
            k, s = r, 1.0
        else:
            e = math.exp(br) if br < 0 else math.exp(-br)
            k = (max(br, 0.0) + math.log1p(e)) / self.floor_beta
            s = 1.0 / (1.0 + e) if br >= 0 else e / (1.0 + e)
        return k, mlp.backward(self._wT, hs, self._w_out * s)

    def packed(self) -> np.ndarray | None:
        """The network as one flat array, the layout the compiled core reads
        (:func:`wholebody.kernels.objectives.mlp_stiffness`): ``[L, beta, b_out, H_max]``,
        then per hidden layer ``[out, in, W (row-major), b]``, then ``w_out``; the
        normalisations are folded in (read-only, made once). None for a subclass that
        evaluates the network otherwise."""
        if type(self).evaluate is not NetworkStiffness.evaluate:
            return None
        if getattr(self, "_packed", None) is None:
            width = max(W.shape[0] for W, _ in self._layers)
            parts = [np.array([len(self._layers), self.floor_beta, self._b_out, width], float)]
            for W, b in self._layers:
                parts += [np.array(W.shape, float), W.ravel(), b]
            parts.append(self._w_out)
            self._packed = np.concatenate(parts)
            self._packed.setflags(write=False)
        return self._packed

    def __repr__(self) -> str:
        return f"NetworkStiffness(hidden={self.hidden_sizes}, tanh)"

    # ----------------------------------------------------------------- file
    def save(self, path: str | Path) -> Path:
        """Write the network (module docstring layout); returns the file written (``.npz``
        appended to a name without it, as numpy does)."""
        numbers = ("k_mean", "k_scale", "floor_beta")
        return self.write(path, FORMAT, numbers)

    @classmethod
    def load(cls, path: str | Path) -> NetworkStiffness:
        """Read a network file.

        Raises
        ------
        DataError
            Not a network file, a missing key, or inconsistent shapes (named).
        """
        return mlp.read_network(path, "stiffness network", cls._read)

    @classmethod
    def _read(cls, path: Path, z: dict[str, np.ndarray]) -> NetworkStiffness:
        """The network in an open file (:meth:`load`)."""
        need = (
            "format",
            "n_layers",
            "activation",
            "x_mean",
            "x_scale",
            "k_mean",
            "k_scale",
            "floor_beta",
        )
        mlp.check_header(path, z, need, FORMAT)
        weights, biases = mlp.read_layers(path, z)
        try:
            return cls(
                weights,
                biases,
                z["x_mean"],
                z["x_scale"],
                z["k_mean"],
                z["k_scale"],
                z["floor_beta"],
                z.get("input_low"),
                z.get("input_high"),
                mlp.read_meta(path, z),
            )
        except DimensionError as exc:
            raise DataError(f"{path}: {exc}") from None


def stiffness_path(robot: object | str) -> Path:
    """Where a robot's trained network lives: ``stiffness.npz`` beside its ``robot.toml``
    (for a bundled robot's name, ``robots/<name>/stiffness.npz``)."""
    if isinstance(robot, str):
        return robots_dir() / robot / "stiffness.npz"
    config = getattr(robot, "config", None)
    if config is None:
        raise DataError(f"expected a Robot or a bundled robot's name, got {robot!r}")
    return Path(config.path).parent / "stiffness.npz"


def default_stiffness(robot: object | str = "mobile_humanoid") -> NetworkStiffness:
    """The trained network of a robot: ``stiffness.npz`` beside its ``robot.toml``.

    ``robot`` is a :class:`~wholebody.robot.Robot` or a bundled robot name.
    """
    path = stiffness_path(robot)
    name = robot if isinstance(robot, str) else str(getattr(robot, "name", ""))
    if not path.is_file():
        raise DataError(
            f"{path}: robot {name!r} has no trained stiffness network there; train "
            f"one with `wholebody stiffness fit --out {path}`"
        )
    return NetworkStiffness.load(path)
