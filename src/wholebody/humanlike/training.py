"""Training the stiffness network with PyTorch (imported here only, never by the package).

The paper's settings are the defaults: mean squared error, Adam, learning rate 0.01, batch
32, 1000 epochs (optionally with decoupled weight decay, see :class:`TrainingConfig`). The
network is that of :mod:`wholebody.arm.network` (tanh hidden layers, normalised input
and output, smooth floor at zero); training minimises ``mean(((k_pred - k) / k_scale)^2)``,
the MSE in units of the label's standard deviation (the same minimiser as the MSE in
N m/rad). Inputs and labels are normalised with the training set's mean and standard
deviation, which are exported with the weights. Training runs in float32 and the weights
are exported as float64.

Requires the ``learn`` extra (``torch``).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from wholebody.arm.network import NetworkStiffness
from wholebody.errors import DataError, SolverError

__all__ = [
    "DEFAULT_HIDDEN",
    "TrainingConfig",
    "TrainingResult",
    "torch_module",
    "train_epoch",
    "train_network",
]

DEFAULT_HIDDEN = (8,)  # fit's default; the shipped network's, chosen by grouped CV
# (fit --select-hidden), is in its card
FLOOR_FRACTION = 0.01  # 1 / floor_beta as a fraction of k_scale


def import_torch() -> ModuleType:
    """PyTorch, imported on first use (only training needs it), or a SolverError that says
    which extra installs it."""
    try:
        import torch
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise SolverError(
            "training the stiffness network needs PyTorch: pip install '.[learn]' from the checkout"
        ) from exc
    return torch


@dataclass(frozen=True)
class TrainingConfig:
    """Training settings: the paper's by default (``hidden`` is this project's choice).

    ``weight_decay`` > 0 switches Adam to AdamW (decoupled weight decay, Loshchilov & Hutter
    2019): each step also shrinks every parameter by ``lr * weight_decay`` of itself, which
    keeps the tanh units from saturating into steep ridges of k. 0 is plain Adam.
    """

    hidden: tuple[int, ...] = DEFAULT_HIDDEN
    epochs: int = 1000
    lr: float = 0.01
    batch_size: int = 32
    seed: int = 0
    weight_decay: float = 0.0


@dataclass
class TrainingResult:
    """The exported network, the loss per epoch (normalised MSE), the torch module and
    the wall time (s)."""

    network: NetworkStiffness
    loss: list[float] = field(default_factory=list)
    module: object = None
    seconds: float = 0.0


def _module(hidden: Sequence[int], x_mean, x_scale, k_mean, k_scale, beta, dtype):
    torch = import_torch()
    nn = torch.nn

    class StiffnessMLP(nn.Module):
        """Same maths as :class:`NetworkStiffness` (see wholebody.arm.network)."""

        def __init__(self) -> None:
            super().__init__()
            sizes = [3, *hidden]
            self.hidden = nn.ModuleList(nn.Linear(a, b) for a, b in itertools.pairwise(sizes))
            self.out = nn.Linear(sizes[-1], 1)
            for name, v in (("x_mean", x_mean), ("x_scale", x_scale)):
                self.register_buffer(name, torch.as_tensor(np.asarray(v), dtype=dtype))
            self.k_mean, self.k_scale, self.beta = float(k_mean), float(k_scale), float(beta)

        def forward(self, p):
            h = (p - self.x_mean) / self.x_scale
            for layer in self.hidden:
                h = torch.tanh(layer(h))
            r = self.k_mean + self.k_scale * self.out(h)[..., 0]
            return torch.nn.functional.softplus(r, beta=self.beta, threshold=30.0)

    return StiffnessMLP().to(dtype)


def torch_module(net: NetworkStiffness, dtype: object = None):
    """A torch module computing exactly ``net`` (float64 by default), for checks."""
    torch = import_torch()
    dtype = dtype or torch.float64
    m = _module(
        net.hidden_sizes, net.x_mean, net.x_scale, net.k_mean, net.k_scale, net.floor_beta, dtype
    )
    with torch.no_grad():
        for layer, W, b in zip([*m.hidden, m.out], net.weights, net.biases, strict=True):
            layer.weight.copy_(torch.as_tensor(W, dtype=dtype))
            layer.bias.copy_(torch.as_tensor(b, dtype=dtype))
    return m


def train_epoch(model, opt, X, y, scale: float, batch_size: int, generator) -> float:
    """One epoch of mini-batch steps of ``opt`` on ``mean(((model(X) - y) / scale)^2)``, the
    batches in a random order drawn from ``generator``; returns the epoch's mean loss. Why
    shared: the stiffness and arm-angle networks train alike."""
    torch = import_torch()
    n = len(y)
    perm = torch.randperm(n, generator=generator)
    total = 0.0
    for i in range(0, n, batch_size):
        idx = perm[i : i + batch_size]
        opt.zero_grad(set_to_none=True)
        err = (model(X[idx]) - y[idx]) / scale
        loss = torch.mean(err * err)
        loss.backward()
        opt.step()
        total += float(loss.detach()) * len(idx)
    return total / n


def train_network(
    X: np.ndarray,
    y: np.ndarray,
    config: TrainingConfig = TrainingConfig(),
    *,
    progress: bool = False,
    on_epoch: Callable[[int, float], None] | None = None,
    meta: dict | None = None,
) -> TrainingResult:
    """Fit the network to canonical wrist positions ``X`` (N, 3) (m) and stiffness ``y`` (N,)
    (N m/rad) with mini-batch Adam; returns the exported numpy network and the loss curve."""
    torch = import_torch()
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float).reshape(-1)
    if X.ndim != 2 or X.shape[1] != 3 or len(X) != len(y) or len(y) < 2:
        raise DataError(f"train_network: need X (N, 3) and y (N,), got {X.shape}, {y.shape}")
    if not (np.isfinite(X).all() and np.isfinite(y).all()):
        raise DataError("train_network: non-finite inputs or labels")
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    x_mean, x_scale = X.mean(0), X.std(0)
    x_scale = np.where(x_scale > 0, x_scale, 1.0)
    k_mean, k_scale = float(y.mean()), float(y.std()) or 1.0
    beta = 1.0 / (FLOOR_FRACTION * k_scale)
    model = _module(config.hidden, x_mean, x_scale, k_mean, k_scale, beta, torch.float32)
    if config.weight_decay > 0:
        opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    else:
        opt = torch.optim.Adam(model.parameters(), lr=config.lr)
    Xt = torch.as_tensor(X, dtype=torch.float32)
    yt = torch.as_tensor(y, dtype=torch.float32)
    n = len(y)
    losses: list[float] = []
    epochs = range(config.epochs)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(epochs, desc="training", unit="epoch")
        epochs = bar
    t0 = time.perf_counter()
    for epoch in epochs:
        losses.append(train_epoch(model, opt, Xt, yt, k_scale, config.batch_size, gen))
        if bar is not None:
            bar.set_postfix(loss=f"{losses[-1]:.4f}")
        if on_epoch is not None:
            on_epoch(epoch, losses[-1])
    seconds = time.perf_counter() - t0
    Ws = [layer.weight.detach().double().numpy() for layer in [*model.hidden, model.out]]
    bs_ = [layer.bias.detach().double().numpy() for layer in [*model.hidden, model.out]]
    info = {
        "training": {
            "hidden": list(config.hidden),
            "activation": "tanh",
            "epochs": config.epochs,
            "lr": config.lr,
            "batch_size": config.batch_size,
            "optimizer": "AdamW" if config.weight_decay > 0 else "Adam",
            "weight_decay": config.weight_decay,
            "loss": "MSE of k / k_scale",
            "seed": config.seed,
            "records": int(n),
            "final_loss": losses[-1] if losses else None,
            "seconds": round(seconds, 1),
            "threads": int(torch.get_num_threads()),
            "torch": str(torch.__version__),
        },
        **(meta or {}),
    }
    net = NetworkStiffness(
        Ws, bs_, x_mean, x_scale, k_mean, k_scale, beta, X.min(0), X.max(0), info
    )
    return TrainingResult(net, losses, model, seconds)
