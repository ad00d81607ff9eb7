"""Inference-only copies of the patch networks: batch norms folded into convolutions, channels-last on CPU.

The kornia networks (AffNet, OriNet, HardNet) alternate ``Conv2d -> BatchNorm2d -> ReLU``. In eval mode a
batch norm is an affine map per channel, so it folds exactly into the preceding convolution's weights and
bias; with the weights in channels-last layout, oneDNN also skips its per-layer reorders; activations run
in place. The throughput of each network, folded and not: docs/performance.md ("CPU figures"). The outputs
equal the original's to float rounding (~1e-6); the network's own ``forward`` is kept.
"""

from __future__ import annotations

import copy

import torch
from torch import nn


def _fold(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> nn.Conv2d:
    """A convolution equal to ``bn(conv(x))`` with ``bn`` in eval mode."""
    scale = (bn.running_var + bn.eps).rsqrt()
    if bn.affine:
        scale = scale * bn.weight
    shift = -bn.running_mean * scale + (bn.bias if bn.affine else 0.0)
    bias = shift if conv.bias is None else conv.bias * scale + shift
    out = nn.Conv2d(
        conv.in_channels,
        conv.out_channels,
        conv.kernel_size,
        conv.stride,
        conv.padding,
        conv.dilation,
        conv.groups,
        bias=True,
        padding_mode=conv.padding_mode,
    ).to(conv.weight.device)
    with torch.no_grad():
        out.weight.copy_(conv.weight * scale[:, None, None, None])
        out.bias.copy_(bias)
    return out


class _InplaceTanh(nn.Module):
    """``tanh`` written over its input (2x faster than allocating the output on CPU)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x.tanh_()


def _fold_sequential(seq: nn.Sequential) -> nn.Sequential:
    """Conv + eval batch-norm pairs folded, dropouts dropped, ReLUs in place, Tanhs in place after a layer
    that returns a fresh tensor (convolution, linear)."""
    layers: list[nn.Module] = []
    mods, i = list(seq), 0
    while i < len(mods):
        m = mods[i]
        nxt = mods[i + 1] if i + 1 < len(mods) else None
        if (
            isinstance(m, nn.Conv2d)
            and isinstance(nxt, nn.BatchNorm2d)
            and nxt.track_running_stats
            and nxt.running_mean is not None
        ):
            layers.append(_fold(m, nxt))
            i += 2
            continue
        if isinstance(m, nn.ReLU):
            m = nn.ReLU(inplace=True)
        elif isinstance(m, nn.Tanh) and layers and isinstance(layers[-1], (nn.Conv2d, nn.Linear)):
            m = _InplaceTanh()
        if not isinstance(m, nn.Dropout):
            layers.append(m)
        i += 1
    return nn.Sequential(*layers)


class _OneDnnConv2d(nn.Module):
    """A convolution on oneDNN tensors (``Tensor.to_mkldnn``) with its weights reordered once for oneDNN."""

    def __init__(self, conv: nn.Conv2d) -> None:
        super().__init__()
        self.padding, self.stride, self.dilation, self.groups = conv.padding, conv.stride, conv.dilation, conv.groups
        weight = conv.weight.detach().contiguous().to_mkldnn()
        self.weight = torch._C._nn.mkldnn_reorder_conv2d_weight(weight, self.padding, self.stride, self.dilation,
                                                                 self.groups)
        bias = conv.bias if conv.bias is not None else torch.zeros(conv.out_channels)
        self.bias = bias.detach().contiguous().to_mkldnn()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.mkldnn_convolution(x, self.weight, self.bias, self.padding, self.stride, self.dilation,
                                        self.groups)


class _OneDnnRun(nn.Module):
    """Consecutive layers run in oneDNN's own tensor layout: one reorder in, one out, instead of one per layer
    (TFeat's convolution + Tanh + max-pool stack: 1.5x faster per patch on CPU; outputs equal to ~1e-5)."""

    def __init__(self, layers: list[nn.Module]) -> None:
        super().__init__()
        self.layers = nn.ModuleList(_OneDnnConv2d(m) if isinstance(m, nn.Conv2d) else m for m in layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x.contiguous().to_mkldnn()
        for layer in self.layers:
            x = layer(x)
        return x.to_dense()


_ONEDNN_LAYERS = (nn.Conv2d, nn.ReLU, _InplaceTanh, nn.MaxPool2d)


def _onednn_runs(seq: nn.Sequential) -> nn.Sequential:
    """``seq`` with every maximal run of oneDNN-capable layers holding a convolution wrapped in a _OneDnnRun."""
    layers: list[nn.Module] = []
    run: list[nn.Module] = []
    for m in [*seq, None]:
        if m is not None and isinstance(m, _ONEDNN_LAYERS):
            run.append(m)
            continue
        has_conv = any(isinstance(r, nn.Conv2d) for r in run)
        layers += [_OneDnnRun(run)] if has_conv else run
        run = []
        if m is not None:
            layers.append(m)
    return nn.Sequential(*layers)


@torch.no_grad()
def fuse_for_inference(net: nn.Module) -> nn.Module:
    """Eval-mode copy of ``net`` with every ``nn.Sequential`` child folded; on CPU, its convolution stacks run
    in oneDNN's layout when PyTorch has oneDNN, else with channels-last weights.

    Args:
        net: a kornia patch network (its parameters' device decides the layout).

    Returns:
        A new module with the same ``forward`` and outputs (to float rounding); ``net`` is untouched.
    """
    out = copy.deepcopy(net).eval()
    param = next(out.parameters(), None)
    cpu = param is not None and param.device.type == "cpu"
    onednn = cpu and torch.backends.mkldnn.is_available()
    for name, child in list(out.named_children()):
        if isinstance(child, nn.Sequential):
            folded = _fold_sequential(child)
            setattr(out, name, _onednn_runs(folded) if onednn else folded)
    out.requires_grad_(False)
    if cpu and not onednn:
        out = out.to(memory_format=torch.channels_last)
    return out
