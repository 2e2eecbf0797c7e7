"""Training the human arm-angle network with PyTorch (imported here only, never by the package).

The network is :class:`~wholebody.arm.human_arm_angle.NetworkArmAngle`: tanh hidden layers
and a linear output, input ``p`` (the normalised wrist) and output ``alpha_h`` (rad), both
standardised with the training set's mean and standard deviation (exported with the
weights). Training minimises the mean squared error in units of the label's sd,
``mean(((alpha_pred - alpha) / alpha_scale)^2)`` (the same minimiser as the MSE in rad^2),
with mini-batch AdamW (decoupled weight decay: it keeps the tanh units out of saturation,
so ``alpha_h`` has no steep ridges for the controller's gradient), seeded, in float64 (the
records are few; the exported weights are the trained ones, bit for bit).

Requires the ``learn`` extra (``torch``).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody.arm.human_arm_angle import NetworkArmAngle
from wholebody.errors import DataError
from wholebody.humanlike.training import import_torch, train_epoch

__all__ = [
    "ArmAngleConfig",
    "ArmAngleTraining",
    "TorchPredictor",
    "torch_arm_angle_module",
    "train_arm_angle",
    "train_predictor",
]


@dataclass(frozen=True)
class ArmAngleConfig:
    """Training settings of the arm-angle network (the shipped network's; its data card
    compares others under the same cross-validation)."""

    hidden: tuple[int, ...] = (8,)
    epochs: int = 100
    lr: float = 0.01
    batch_size: int = 256
    weight_decay: float = 0.01
    seed: int = 0


@dataclass
class ArmAngleTraining:
    """The exported network, the loss per epoch (normalised MSE), the torch module and the
    wall time (s)."""

    network: NetworkArmAngle
    loss: list[float] = field(default_factory=list)
    module: object = None
    seconds: float = 0.0


def _module(hidden: Sequence[int], x_mean, x_scale, a_mean: float, a_scale: float, dtype):
    """The torch network; its input width is that of ``x_mean``."""
    torch = import_torch()
    nn = torch.nn

    class ArmAngleMLP(nn.Module):
        """Same maths as :class:`NetworkArmAngle` (see wholebody.arm.human_arm_angle)."""

        def __init__(self) -> None:
            super().__init__()
            sizes = [len(x_mean), *hidden]
            self.hidden = nn.ModuleList(nn.Linear(a, b) for a, b in itertools.pairwise(sizes))
            self.out = nn.Linear(sizes[-1], 1)
            for name, v in (("x_mean", x_mean), ("x_scale", x_scale)):
                self.register_buffer(name, torch.as_tensor(np.asarray(v), dtype=dtype))
            self.a_mean, self.a_scale = float(a_mean), float(a_scale)

        def forward(self, p):
            h = (p - self.x_mean) / self.x_scale
            for layer in self.hidden:
                h = torch.tanh(layer(h))
            return self.a_mean + self.a_scale * self.out(h)[..., 0]

    return ArmAngleMLP().to(dtype)


def torch_arm_angle_module(net: NetworkArmAngle):
    """A float64 torch module computing exactly ``net``, for checks."""
    torch = import_torch()
    m = _module(
        net.hidden_sizes, net.x_mean, net.x_scale, net.alpha_mean, net.alpha_scale, torch.float64
    )
    with torch.no_grad():
        for layer, W, b in zip([*m.hidden, m.out], net.weights, net.biases, strict=True):
            layer.weight.copy_(torch.as_tensor(W, dtype=torch.float64))
            layer.bias.copy_(torch.as_tensor(b, dtype=torch.float64))
    return m


@dataclass
class TorchPredictor:
    """A trained torch network with ``predict(X) -> alpha`` (rad) on numpy inputs (N, d): the
    comparisons' models with other inputs than the normalised wrist (the hand direction)."""

    module: object
    loss: list[float]
    seconds: float

    def predict(self, X: np.ndarray) -> np.ndarray:
        torch = import_torch()
        with torch.no_grad():
            return self.module(torch.as_tensor(np.asarray(X, dtype=float))).numpy()  # type: ignore[operator]


def _fit(X: np.ndarray, y: np.ndarray, config: ArmAngleConfig):
    """Train on inputs ``X`` (N, d) and labels ``y`` (N,) (module docstring); returns the
    module, the loss per epoch and the wall time (s)."""
    torch = import_torch()
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float).reshape(-1)
    if X.ndim != 2 or len(X) != len(y) or len(y) < 2:
        raise DataError(
            f"arm-angle training: need inputs (N, d) and labels (N,), got {X.shape}, {y.shape}"
        )
    if not (np.isfinite(X).all() and np.isfinite(y).all()):
        raise DataError("arm-angle training: non-finite inputs or labels")
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    x_scale = X.std(0)
    x_scale = np.where(x_scale > 0, x_scale, 1.0)
    a_scale = float(y.std()) or 1.0
    model = _module(config.hidden, X.mean(0), x_scale, float(y.mean()), a_scale, torch.float64)
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    Xt, yt = torch.as_tensor(X), torch.as_tensor(y)
    t0 = time.perf_counter()
    losses = [
        train_epoch(model, opt, Xt, yt, a_scale, config.batch_size, gen)
        for _ in range(config.epochs)
    ]
    return model, losses, time.perf_counter() - t0


def train_predictor(X: np.ndarray, y: np.ndarray, config: ArmAngleConfig) -> TorchPredictor:
    """Train the same network on any inputs ``X`` (N, d); kept in torch (for comparisons)."""
    model, losses, seconds = _fit(X, y, config)
    model.eval()
    return TorchPredictor(model, losses, seconds)


def train_arm_angle(
    P: np.ndarray,
    alpha: np.ndarray,
    config: ArmAngleConfig = ArmAngleConfig(),
    *,
    spread: tuple[float, float, float] = (0.0, 0.0, 0.0),
    meta: dict | None = None,
) -> ArmAngleTraining:
    """Fit the network to normalised wrists ``P`` (N, 3) and arm angles ``alpha`` (N,) (rad).

    ``spread`` = (in all, between, within persons) (rad) is stored in the network as is: it
    comes from the cross-validation (:mod:`wholebody.humanlike.arm_angle_scores`), not from
    this fit's own residuals.
    """
    torch = import_torch()
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise DataError(f"train_arm_angle: need P (N, 3), got {P.shape}")
    model, losses, seconds = _fit(P, alpha, config)
    layers = [*model.hidden, model.out]
    info = {
        "training": {
            "hidden": list(config.hidden),
            "activation": "tanh",
            "epochs": config.epochs,
            "lr": config.lr,
            "batch_size": config.batch_size,
            "optimizer": "AdamW",
            "weight_decay": config.weight_decay,
            "loss": "MSE of alpha / alpha_scale",
            "seed": config.seed,
            "records": len(P),
            "final_loss": losses[-1] if losses else None,
            "seconds": round(seconds, 1),
            "threads": int(torch.get_num_threads()),
            "torch": str(torch.__version__),
        },
        **(meta or {}),
    }
    net = NetworkArmAngle(
        [layer.weight.detach().numpy().copy() for layer in layers],
        [layer.bias.detach().numpy().copy() for layer in layers],
        model.x_mean.numpy().copy(),
        model.x_scale.numpy().copy(),
        model.a_mean,
        model.a_scale,
        spread[0],
        spread_between=spread[1],
        spread_within=spread[2],
        input_low=P.min(0),
        input_high=P.max(0),
        meta=info,
    )
    return ArmAngleTraining(net, losses, model, seconds)
