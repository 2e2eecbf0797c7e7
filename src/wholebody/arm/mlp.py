"""The tanh multilayer perceptron the shipped networks share, in numpy (no torch at run time).

Both the stiffness network (:mod:`wholebody.arm.network`) and the human arm-angle network
(:mod:`wholebody.arm.human_arm_angle`) are, before their own last step::

    z   = (p - x_mean) / x_scale                       p: the input (3,)
    h_1 = tanh(W_1 z + b_1),  h_i = tanh(W_i h_{i-1} + b_i)
    r   = y_mean + y_scale (w_out . h_L + b_out)

with the normalisations folded into the first and last layers once
(``W_1 z + b_1 = (W_1 / x_scale) p + (b_1 - (W_1 / x_scale) x_mean)``), and the gradient
by the chain rule::

    dr/dp = y_scale w_out^T D_L W_L ... D_1 W_1 / x_scale,   D_i = diag(1 - h_i^2)

This module holds that core (checks, folding, forward and backward passes) and what their
``.npz`` files share (``format``, ``activation``, ``n_layers``, ``W0``, ``b0``, ...,
``input_low``/``input_high``, ``meta``), so that the two networks validate, write and read
their files the same way. Every check raises
:class:`~wholebody.errors.DimensionError` naming the network (``who``); the file readers
raise :class:`~wholebody.errors.DataError` naming the file.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np

from wholebody.errors import DataError, DimensionError
from wholebody.files import read_npz, write_npz
from wholebody.resources import npz_path

T = TypeVar("T")

__all__ = [
    "Folded",
    "TanhNetwork",
    "backward",
    "backward_batch",
    "check_header",
    "check_layers",
    "fold",
    "forward",
    "forward_states",
    "layer_arrays",
    "number",
    "read_layers",
    "read_meta",
    "read_network",
    "vector3",
    "write_network",
]

Folded = tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, float]
"""``(layers, w_out, b_out)``: hidden layers ``(W, b)`` with the input normalisation in the
first, and the output row and bias with the output normalisation in them."""


class TanhNetwork:
    """What the shipped networks share beyond the maths: their sizes and the box of their
    training inputs (``input_low``/``input_high``, or None)."""

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    x_mean: np.ndarray
    x_scale: np.ndarray
    input_low: np.ndarray | None
    input_high: np.ndarray | None
    meta: dict

    def in_range(self, P: np.ndarray) -> np.ndarray:
        """Whether points (..., 3) lie in the bounding box of the training inputs. Why: outside
        it the network extrapolates (its tanh units saturate)."""
        if self.input_low is None or self.input_high is None:
            raise DataError(f"this {type(self).__name__} has no stored training range")
        P = np.asarray(P, dtype=float)
        return np.all((self.input_low <= P) & (self.input_high >= P), axis=-1)

    @property
    def hidden_sizes(self) -> tuple[int, ...]:
        return tuple(w.shape[0] for w in self.weights[:-1])

    def write(self, path: str | Path, fmt: str, numbers: Sequence[str]) -> Path:
        """:func:`write_network` of this network: its layers, its input standardisation
        (``x_mean``, ``x_scale``), the scalar attributes ``numbers``, its training box and
        ``meta``; the file written (``.npz`` appended to a name without it)."""
        own = {
            "x_mean": self.x_mean,
            "x_scale": self.x_scale,
            **{k: np.array(getattr(self, k)) for k in numbers},
        }
        box = (self.input_low, self.input_high)
        return write_network(path, fmt, self.weights, self.biases, own, box, self.meta)


def vector3(value: object, name: str, who: str) -> np.ndarray:
    """``value`` as a float (3,) array, or DimensionError naming ``who`` and ``name``."""
    a = np.array(value, dtype=float)
    if a.shape != (3,):
        raise DimensionError(f"{who}: {name} must have shape (3,), got {a.shape}")
    return a


def number(value: object, name: str, who: str) -> float:
    """``value`` as a float (a 1-element array is fine), or DimensionError naming it."""
    a = np.asarray(value, dtype=float)
    if a.size != 1:
        raise DimensionError(f"{who}: {name} must be a number, got shape {a.shape}")
    return float(a.reshape(()))


def check_layers(
    weights: Sequence[np.ndarray], biases: Sequence[np.ndarray], who: str, n_in: int = 3
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Weights ``(out, in)`` and biases ``(out,)`` as float arrays, chained from ``n_in``
    inputs to 1 output through at least one hidden layer; DimensionError otherwise."""
    if len(weights) != len(biases) or len(weights) < 2:
        raise DimensionError(
            f"{who}: need matching weights and biases for at least one "
            "hidden layer and the output layer"
        )
    Ws = [np.array(w, dtype=float) for w in weights]
    bs = [np.array(b, dtype=float).reshape(-1) for b in biases]
    fan_in = n_in
    for i, (w, b) in enumerate(zip(Ws, bs, strict=True)):
        if w.ndim != 2 or w.shape[1] != fan_in or b.shape != (w.shape[0],):
            raise DimensionError(
                f"{who}: layer {i}: weight {w.shape} and bias {b.shape} do "
                f"not fit an input of {fan_in}"
            )
        fan_in = w.shape[0]
    if fan_in != 1:
        raise DimensionError(f"{who}: the output layer must have 1 unit")
    return Ws, bs


def fold(
    weights: Sequence[np.ndarray],
    biases: Sequence[np.ndarray],
    x_mean: np.ndarray,
    x_scale: np.ndarray,
    y_mean: float,
    y_scale: float,
) -> Folded:
    """The normalisations folded into the first and last layers (module docstring)."""
    W1 = weights[0] / x_scale
    layers = [(W1, biases[0] - W1 @ x_mean)]
    layers += list(zip(weights[1:-1], biases[1:-1], strict=True))
    return layers, y_scale * weights[-1][0], float(y_mean + y_scale * biases[-1][0])


def forward(layers: Sequence[tuple[np.ndarray, np.ndarray]], P: np.ndarray) -> list[np.ndarray]:
    """Hidden states ``[h_1, ..., h_L]`` for points (..., n_in), vectorised."""
    hs = []
    h = np.asarray(P, dtype=float)
    for W, b in layers:
        h = np.tanh(h @ W.T + b)
        hs.append(h)
    return hs


def forward_states(layers: Sequence[tuple[np.ndarray, np.ndarray]], p: np.ndarray) -> list:
    """Hidden states of one point (n_in,): matrix-vector products, the fastest for one."""
    hs = []
    h = p
    for W, b in layers:
        h = np.tanh(W @ h + b)
        hs.append(h)
    return hs


def backward_batch(
    layers: Sequence[tuple[np.ndarray, np.ndarray]], hs: Sequence[np.ndarray], g: np.ndarray
) -> np.ndarray:
    """``g`` (..., H_L), the derivative with respect to ``h_L``, carried back to the input:
    ``g <- (g * (1 - h_i^2)) W_i`` from the last hidden layer to the first."""
    for (W, _), h in zip(reversed(layers), reversed(hs), strict=True):
        g = (g * (1.0 - h * h)) @ W
    return g


def backward(wT: Sequence[np.ndarray], hs: Sequence[np.ndarray], g: np.ndarray) -> np.ndarray:
    """:func:`backward_batch` for one point, with the transposed weights ``wT`` made once."""
    for WT, h in zip(reversed(wT), reversed(hs), strict=True):
        g = WT @ (g * (1.0 - h * h))
    return g


def layer_arrays(weights: Sequence[np.ndarray], biases: Sequence[np.ndarray]) -> dict:
    """The layer keys of a network file: ``n_layers``, ``W0``, ``b0``, ..."""
    out: dict[str, np.ndarray] = {"n_layers": np.array(len(weights))}
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        out[f"W{i}"], out[f"b{i}"] = w, b
    return out


def read_layers(path: Path, z: dict[str, np.ndarray]) -> tuple[list, list]:
    """The weights and biases of an open network file; DataError naming a missing layer key
    or one beyond ``n_layers``."""
    if "n_layers" not in z:
        raise DataError(f"{path}: missing key(s) n_layers")
    n = int(z["n_layers"])
    keys = [f"{p}{i}" for i in range(n) for p in ("W", "b")]
    missing = [k for k in keys if k not in z]
    if missing:
        raise DataError(f"{path}: missing layer key(s) {', '.join(missing)}")
    extra = [k for k in z if k[:1] in "Wb" and k[1:].isdigit() and k not in keys]
    if extra:
        raise DataError(f"{path}: layer key(s) {', '.join(extra)} beyond n_layers = {n}")
    return [z[f"W{i}"] for i in range(n)], [z[f"b{i}"] for i in range(n)]


def read_meta(path: Path, z: dict[str, np.ndarray]) -> dict:
    """The ``meta`` key (a 0-d JSON string) of an open network file; ``{}`` without it."""
    if "meta" not in z:
        return {}
    try:
        meta = json.loads(str(z["meta"]))
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: key 'meta' is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise DataError(f"{path}: key 'meta' must be a JSON object, got {type(meta).__name__}")
    return meta


def write_network(
    path: str | Path,
    fmt: str,
    weights: Sequence[np.ndarray],
    biases: Sequence[np.ndarray],
    arrays: dict[str, np.ndarray],
    box: tuple[np.ndarray | None, np.ndarray | None],
    meta: dict,
) -> Path:
    """Write a network file (atomically, no pickle): ``format`` ``fmt``, ``activation``
    "tanh", the layers, the network's own ``arrays``, the training box ``input_low`` /
    ``input_high`` when both are given and ``meta`` as JSON. Returns the file written
    (``.npz`` appended to a name without it, as numpy does)."""
    out = {
        "format": np.array(fmt),
        "activation": np.array("tanh"),
        **arrays,
        "meta": np.array(json.dumps(meta, sort_keys=True)),
        **layer_arrays(weights, biases),
    }
    if box[0] is not None and box[1] is not None:  # else: no range stored
        out["input_low"], out["input_high"] = box
    return write_npz(npz_path(path), out, compress=False)


def check_header(path: Path, z: dict[str, np.ndarray], need: Sequence[str], fmt: str) -> None:
    """DataError naming the file unless it has the keys ``need``, the format ``fmt`` and the
    tanh activation."""
    missing = [k for k in need if k not in z]
    if missing:
        raise DataError(f"{path}: missing key(s) {', '.join(missing)}")
    if str(z["format"]) != fmt:
        raise DataError(f"{path}: format {str(z['format'])!r}, expected {fmt!r}")
    if str(z["activation"]) != "tanh":
        raise DataError(f"{path}: activation {str(z['activation'])!r} is not supported")


def read_network(path: str | Path, what: str, read: Callable[[Path, dict], T]) -> T:
    """``read(path, arrays)`` of the ``.npz`` at ``path``; any fault is a DataError naming the
    file (``what``: "stiffness network", ...), numpy's own ``ValueError``/``TypeError`` on a
    malformed array (an object array, never unpickled) included."""
    path = Path(path)
    z = read_npz(path, what)
    try:
        return read(path, z)
    except DataError:
        raise
    except (ValueError, TypeError) as exc:
        raise DataError(f"{path}: not a readable {what} ({exc})") from None
