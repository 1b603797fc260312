"""Fitting :class:`~hopper_sim.controller.hop_model.HopNet` to a :class:`HopDataset`.

Loss per mini-batch (standardised units):

    L = mean_{ok} ||z_pred - z_true||^2 / 5  +  w_f * BCE(logit, ok)

The regression term uses the successful hops only (failed hops have no next state); the
feasibility term uses every hop, so the network learns where hops fail. A held-out split
(``test_fraction``) is never trained on; :func:`evaluate` reports per-output RMSE and 95th
percentile absolute error on it, and the feasibility classifier's accuracy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from hopper_sim.controller.dataset import HopDataset
from hopper_sim.controller.errors import DatasetError
from hopper_sim.controller.hop_model import OUTPUT_NAMES, HopNet


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings (Adam with cosine learning-rate decay)."""

    hidden: tuple[int, ...] = (128, 128, 128)
    epochs: int = 60
    batch_size: int = 512
    lr: float = 3e-3
    weight_decay: float = 0.0
    feasibility_weight: float = 0.5
    test_fraction: float = 0.1


@dataclass
class TrainResult:
    """The fitted network, the split used and the held-out metrics."""

    net: HopNet
    train_index: np.ndarray
    test_index: np.ndarray
    metrics: dict[str, dict[str, float]] = field(default_factory=dict)
    loss_history: list[float] = field(default_factory=list)


def split_indices(n: int, test_fraction: float, rng: np.random.Generator):
    """Random disjoint ``(train, test)`` index arrays with ``round(n * test_fraction)`` tests."""
    if not 0.0 < test_fraction < 1.0:
        raise DatasetError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    perm = rng.permutation(n)
    n_test = max(1, round(n * test_fraction))
    if n_test >= n:
        raise DatasetError(f"dataset of {n} hops is too small for a test split")
    return np.sort(perm[n_test:]), np.sort(perm[:n_test])


def train_hop_model(
    dataset: HopDataset,
    config: TrainConfig = TrainConfig(),
    *,
    seed: int,
    progress: Callable[[int, float], None] | None = None,
) -> TrainResult:
    """Train a :class:`HopNet` on ``dataset``; ``seed`` fixes the split, the initial weights
    and the batch order. ``progress(epoch, mean_loss)`` is called after each epoch."""
    ok = dataset.ok
    if ok.sum() < 2:
        raise DatasetError(f"dataset has {int(ok.sum())} successful hops; need at least 2")
    rng = np.random.default_rng(seed)
    train_idx, test_idx = split_indices(len(dataset), config.test_fraction, rng)
    train_ok = train_idx[ok[train_idx]]
    mean = dataset.outputs[train_ok].mean(axis=0)
    std = dataset.outputs[train_ok].std(axis=0)
    std = np.where(std > 1e-9, std, 1.0)

    torch.manual_seed(int(rng.integers(2**31)))
    net = HopNet(dataset.ranges, mean, std, hidden=config.hidden)
    x = torch.as_tensor(dataset.inputs[train_idx], dtype=torch.float32)
    y = torch.as_tensor(
        np.nan_to_num(dataset.outputs[train_idx]), dtype=torch.float32
    )  # failed rows masked
    z = net.output_scaler(y)
    m = torch.as_tensor(ok[train_idx])
    label = m.float()

    opt = torch.optim.Adam(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    steps_per_epoch = max(1, int(np.ceil(len(train_idx) / config.batch_size)))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.epochs * steps_per_epoch)
    bce = nn.BCEWithLogitsLoss()
    history: list[float] = []
    for epoch in range(config.epochs):
        order = torch.as_tensor(rng.permutation(len(train_idx)))
        total = 0.0
        for b in range(steps_per_epoch):
            idx = order[b * config.batch_size : (b + 1) * config.batch_size]
            pred, logit = net.forward_standardised(x[idx])
            mb = m[idx]
            reg = ((pred[mb] - z[idx][mb]) ** 2).mean() if mb.any() else pred.sum() * 0.0
            loss = reg + config.feasibility_weight * bce(logit, label[idx])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach())
        history.append(total / steps_per_epoch)
        if progress is not None:
            progress(epoch, history[-1])
    net.eval()
    return TrainResult(net, train_idx, test_idx, evaluate(net, dataset, test_idx), history)


def evaluate(net: HopNet, dataset: HopDataset, index: np.ndarray) -> dict[str, dict[str, float]]:
    """Held-out errors: per output ``{"rmse", "p95"}`` (physical units, successful hops only)
    and ``"feasibility": {"accuracy", "false_ok_rate", "n"}`` (false_ok_rate: fraction of the
    failed hops predicted to succeed)."""
    y_pred, p_ok = net.predict(dataset.inputs[index])
    ok = dataset.ok[index]
    err = np.abs(y_pred[ok] - dataset.outputs[index][ok])
    metrics: dict[str, dict[str, float]] = {}
    for j, name in enumerate(OUTPUT_NAMES):
        e = err[:, j]
        metrics[name] = {
            "rmse": float(np.sqrt(np.mean(e**2))) if len(e) else float("nan"),
            "p95": float(np.percentile(e, 95)) if len(e) else float("nan"),
        }
    pred_ok = p_ok > 0.5
    metrics["feasibility"] = {
        "accuracy": float(np.mean(pred_ok == ok)),
        "false_ok_rate": float(np.mean(pred_ok[~ok])) if (~ok).any() else 0.0,
        "n": float(len(index)),
    }
    return metrics
