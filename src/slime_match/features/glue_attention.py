"""LightGlue's cross-attention off CUDA as two fused attentions, for kornia's LightGlue and LighterGlue.

A cross-attention layer lets each image's tokens attend to the other's: ``softmax(q0 q1^T s) v1`` for image 0
and ``softmax(q1 q0^T s) v0`` for image 1, with the same projections ``q`` of both sides (``s``: the head
dimension to the power -1/2). kornia computes them, off CUDA, through the (B, heads, M, N) similarity matrix
itself: one product, a softmax along each side (one of them on a transposed copy) and two products, four
passes over a matrix of 150 MB per layer at 3072 x 3072 keypoints and four heads. :class:`FusedCrossBlock`
runs them as two calls of torch's ``scaled_dot_product_attention``, whose CPU kernel streams the similarities
block by block and never holds the matrix: the similarities are computed twice, the memory traffic falls to a
fraction. Same weights, same operations up to float rounding; on CUDA, and for the masked inputs of kornia's
compiled path, kornia's own forward runs.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from kornia.feature.lightglue import CrossBlock
from torch import nn


class FusedCrossBlock(CrossBlock):
    """kornia's ``CrossBlock`` whose forward, off CUDA and without a mask, runs the two attentions fused."""

    def forward(self, x0: torch.Tensor, x1: torch.Tensor, mask: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, M, D) and (B, N, D) descriptors of images 0 and 1, updated by one round of cross-attention."""
        if mask is not None or x0.device.type == "cuda":
            return super().forward(x0, x1, mask)

        def heads(t: torch.Tensor) -> torch.Tensor:  # (B, L, D) -> (B, heads, L, D / heads)
            return t.unflatten(-1, (self.heads, -1)).transpose(1, 2).contiguous()

        qk0, qk1 = (heads(t) for t in self.map_(self.to_qk, x0, x1))
        v0, v1 = (heads(t) for t in self.map_(self.to_v, x0, x1))
        m0 = F.scaled_dot_product_attention(qk0, qk1, v1, scale=self.scale)
        m1 = F.scaled_dot_product_attention(qk1, qk0, v0, scale=self.scale)
        m0, m1 = self.map_(lambda t: self.to_out(t.transpose(1, 2).flatten(start_dim=-2)), m0, m1)
        return x0 + self.ffn(torch.cat([x0, m0], -1)), x1 + self.ffn(torch.cat([x1, m1], -1))


def fuse_cross_attention(glue: nn.Module) -> nn.Module:
    """``glue`` (kornia's LightGlue) with each cross-attention block running as :class:`FusedCrossBlock`
    (in place: the blocks keep their weights); returns ``glue``."""
    for block in glue.modules():
        if type(block) is CrossBlock:
            block.__class__ = FusedCrossBlock
    return glue
