"""Nearest-neighbour descriptor matching: NN ratio, mutual NN (with or without a ratio test) and FGINN, on
blocked L2 distances.

The N x M distance matrix is never held in memory: rows are processed in blocks of ``block_size`` and
only the k smallest distances per row and per column are kept. The same primitives serve Blob matching.
"""

from __future__ import annotations

import numpy as np
import torch

from ..errors import ConfigError
from ..types import Matches
from . import nn_kernels

DEFAULT_BLOCK = 1024


def _sq_dist_block(a: torch.Tensor, b: torch.Tensor, b_sq: torch.Tensor) -> torch.Tensor:
    """(B, M) squared L2 distances of a (B, D) block to b (M, D); may be slightly negative (rounding)."""
    return torch.addmm(b_sq[None, :], a, b.T, alpha=-2.0).add_((a * a).sum(1, keepdim=True))


def _smallest(d: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The k <= M smallest entries of each row of a (B, M) matrix, ascending: values (B, k) and indices (B, k).

    On CPU a compiled pass (``nn_kernels.smallest_rows``: equal values go to the lowest index, NaN last; about
    5x faster than ``torch.topk`` on Slime's matrices of a few hundred squared). Elsewhere, and where NaN
    entries call for it, ``torch.topk``.
    """
    if d.device.type == "cpu":
        vals, idx, ok = nn_kernels.smallest_rows(np.ascontiguousarray(d.detach().numpy()), k)
        if ok:
            return torch.from_numpy(vals), torch.from_numpy(idx)
    return torch.topk(d, k, dim=1, largest=False, sorted=True)


def _smallest_cols(d: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``_smallest(d.T, k)`` for a (B, M) matrix, k <= B: values (M, k) and row indices (M, k); on CPU without
    transposing d (``nn_kernels.smallest_cols``)."""
    if d.device.type == "cpu":
        vals, idx, ok = nn_kernels.smallest_cols(np.ascontiguousarray(d.detach().numpy()), k)
        if ok:
            return torch.from_numpy(vals), torch.from_numpy(idx)
    return torch.topk(d.T, k, dim=1, largest=False, sorted=True)


def knn(desc0: torch.Tensor, desc1: torch.Tensor, k_rows: int, k_cols: int = 0,
        block_size: int = DEFAULT_BLOCK) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """k nearest neighbours along the rows and the columns of the L2 distance matrix, in row blocks.

    Args:
        desc0: (N, D) descriptors of image 0 (rows).
        desc1: (M, D) descriptors of image 1 (columns), same device.
        k_rows: neighbours kept per row (clipped to M).
        k_cols: neighbours kept per column (clipped to N); 0 skips the column search.
        block_size: rows per block; peak extra memory is about 2 * block_size * M floats.

    Returns:
        row_dist (N, kr), row_idx (N, kr): ascending distances from each row to its nearest columns;
        col_dist (M, kc), col_idx (M, kc): ascending distances from each column to its nearest rows.
    """
    if block_size < 1:
        raise ConfigError(f"block_size must be >= 1, got {block_size}")
    a = desc0.float()
    b = desc1.float()
    n, m = a.shape[0], b.shape[0]
    kr, kc = min(k_rows, m), min(k_cols, n)
    dev = a.device
    row_dist = torch.empty(n, kr, device=dev)
    row_idx = torch.empty(n, kr, dtype=torch.long, device=dev)
    col_vals, col_inds = [], []
    b_sq = (b * b).sum(1)
    for start in range(0, n, block_size):
        d = _sq_dist_block(a[start:start + block_size], b, b_sq)
        if kr > 0:
            row_dist[start:start + d.shape[0]], row_idx[start:start + d.shape[0]] = _smallest(d, kr)
        if kc > 0:
            val, idx = _smallest_cols(d, min(kc, d.shape[0]))  # (M, k) per block, merged below
            col_vals.append(val)
            col_inds.append(idx + start)
    if kc > 0:
        col_dist, col_idx = col_vals[0], col_inds[0]
        if len(col_vals) > 1:  # merge the blocks' lists
            col_dist, pick = _smallest(torch.cat(col_vals, 1), kc)
            col_idx = torch.gather(torch.cat(col_inds, 1), 1, pick)
        col_dist = col_dist.clamp_min(0.0).sqrt()
    else:
        col_dist = torch.empty(m, 0, device=dev)
        col_idx = torch.empty(m, 0, dtype=torch.long, device=dev)
    return row_dist.clamp_min_(0.0).sqrt_(), row_idx, col_dist, col_idx


def nearest_far(query: torch.Tensor, desc: torch.Tensor, xy: torch.Tensor, anchor: torch.Tensor,
                radius: float, nn_dist: torch.Tensor, nn_idx: torch.Tensor,
                block_size: int = DEFAULT_BLOCK, rows: torch.Tensor | None = None) -> torch.Tensor:
    """Distance from each query descriptor to its nearest descriptor located farther than radius from an anchor.

    The sorted k-NN lists answer most queries exactly (the first far entry is the global answer); queries
    whose k nearest are all near the anchor are recomputed against every descriptor, in blocks.

    Args:
        query: (P, D) query descriptors.
        desc: (M, D) descriptors searched; xy: (M, 2) their keypoint positions in pixels.
        anchor: (P, 2) position around which competitors are ignored; radius: in pixels.
        nn_dist, nn_idx: (P, k) ascending distances / indices of each query's k nearest in ``desc``.
        block_size: queries per block of the exact fallback.
        rows: (P,) optional: query q is row rows[q] of query, nn_dist and nn_idx, which then hold any number
            of rows (spares gathering copies of them).

    Returns:
        (P,) float32 distances; inf where every descriptor is within radius of the anchor.
    """
    p = anchor.shape[0]
    if p == 0 or desc.shape[0] == 0:
        return torch.full((p,), float("inf"), device=anchor.device)
    if rows is None:
        rows = torch.arange(p, device=anchor.device)
    if anchor.device.type == "cpu":
        xy_np, anchor_np = xy.detach().numpy(), anchor.detach().numpy()
        r2 = np.result_type(xy_np, anchor_np).type(radius * radius)  # the precision torch compares in
        out, rest = nn_kernels.first_far(nn_dist.numpy(), nn_idx.numpy(), rows.numpy(), xy_np, anchor_np, r2)
        out, rest = torch.from_numpy(out), torch.from_numpy(rest)
    else:
        lists_dist, lists_idx = nn_dist[rows], nn_idx[rows]
        out = torch.full((p,), float("inf"), device=anchor.device)
        far = ((xy[lists_idx] - anchor[:, None, :]).square().sum(-1) > radius * radius)
        has_far = far.any(1)
        first = far.float().argmax(1)
        out[has_far] = lists_dist[has_far, first[has_far]]
        rest = torch.nonzero(~has_far).flatten()
    if rest.numel() and nn_idx.shape[1] < desc.shape[0]:
        b = desc.float()
        b_sq = (b * b).sum(1)
        for start in range(0, rest.numel(), block_size):
            sel = rest[start:start + block_size]
            d = _sq_dist_block(query[rows[sel]].float(), b, b_sq)
            near = (xy[None, :, :] - anchor[sel][:, None, :]).square().sum(-1) <= radius * radius
            out[sel] = d.masked_fill_(near, float("inf")).amin(1).clamp_min(0.0).sqrt()
    return out


def _to_matches(idx0: torch.Tensor, idx1: torch.Tensor, scores: torch.Tensor) -> Matches:
    """Matches sorted by ascending score (stable), as numpy."""
    s = scores.detach().double().cpu().numpy()
    order = np.argsort(s, kind="stable")
    return Matches(idx0.cpu().numpy()[order], idx1.cpu().numpy()[order], s[order])


def _check_ratio(ratio: float) -> None:
    if not 0 < ratio <= 1:
        raise ConfigError(f"ratio must be in (0, 1], got {ratio}")


def _nn_ratio(desc0: torch.Tensor, desc1: torch.Tensor, k_cols: int,
              block_size: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Each row's two nearest columns (N, 2) (one when M < 2), each column's ``k_cols`` nearest rows, and the
    (N,) ratio d1 / d2 (d2 = inf when M < 2)."""
    dist, idx, _, col_idx = knn(desc0, desc1, 2, k_cols, block_size)
    second = dist[:, 1] if dist.shape[1] > 1 else torch.full_like(dist[:, 0], float("inf"))
    return idx, col_idx, _ratio(dist[:, 0], second)


def match_nn_ratio(desc0: torch.Tensor, desc1: torch.Tensor, ratio: float = 0.8,
                   block_size: int = DEFAULT_BLOCK) -> Matches:
    """Lowe's nearest-neighbour ratio test.

    Args:
        desc0: (N, D), desc1: (M, D) descriptors.
        ratio: keep i -> nn(i) when d1 / d2 < ratio (d2 = inf when M < 2).

    Returns:
        Matches with score d1 / d2, ascending.
    """
    _check_ratio(ratio)
    if desc0.shape[0] == 0 or desc1.shape[0] == 0:
        return Matches.empty()
    idx, _, score = _nn_ratio(desc0, desc1, 0, block_size)
    keep = torch.nonzero(score < ratio).flatten()
    return _to_matches(keep, idx[keep, 0], score[keep])


def match_mutual_nn(desc0: torch.Tensor, desc1: torch.Tensor, block_size: int = DEFAULT_BLOCK) -> Matches:
    """Mutual nearest neighbours: i -> j and j -> i.

    Returns:
        Matches with score = L2 descriptor distance, ascending.
    """
    if desc0.shape[0] == 0 or desc1.shape[0] == 0:
        return Matches.empty()
    dist, idx, _, col_idx = knn(desc0, desc1, 1, 1, block_size)
    rows = torch.arange(desc0.shape[0], device=idx.device)
    keep = torch.nonzero(col_idx[idx[:, 0], 0] == rows).flatten()
    return _to_matches(keep, idx[keep, 0], dist[keep, 0])


def match_mutual_nn_ratio(desc0: torch.Tensor, desc1: torch.Tensor, ratio: float = 0.9,
                          block_size: int = DEFAULT_BLOCK) -> Matches:
    """Mutual nearest neighbours that also pass Lowe's ratio test.

    Args:
        desc0: (N, D), desc1: (M, D) descriptors.
        ratio: keep i -> nn(i) when d1 / d2 < ratio (d2 = inf when M < 2); 1 keeps every mutual pair.

    Returns:
        Matches with score d1 / d2, ascending.
    """
    _check_ratio(ratio)
    if desc0.shape[0] == 0 or desc1.shape[0] == 0:
        return Matches.empty()
    idx, col_idx, score = _nn_ratio(desc0, desc1, 1, block_size)
    ok = col_idx[idx[:, 0], 0] == torch.arange(desc0.shape[0], device=idx.device)
    if ratio < 1:
        ok &= score < ratio
    keep = torch.nonzero(ok).flatten()
    return _to_matches(keep, idx[keep, 0], score[keep])


def match_fginn(desc0: torch.Tensor, desc1: torch.Tensor, xy0: torch.Tensor, xy1: torch.Tensor,
                ratio: float = 0.8, spatial_radius: float = 10.0, mutual: bool = False, k: int = 10,
                block_size: int = DEFAULT_BLOCK) -> Matches:
    """First Geometrically Inconsistent Nearest Neighbour ratio (Mishkin et al.).

    The second neighbour of the ratio is the nearest descriptor whose keypoint lies farther than
    ``spatial_radius`` from the first neighbour's keypoint, so near-duplicate detections at the same place
    do not veto a distinctive match.

    Args:
        desc0: (N, D), desc1: (M, D) descriptors; xy0: (N, 2), xy1: (M, 2) keypoint positions in pixels
            (only image 1's positions matter; xy0 keeps the signature symmetric).
        ratio: keep when d1 / d_fginn < ratio.
        spatial_radius: radius in pixels around the first neighbour inside which competitors are ignored.
        mutual: also require i to be the nearest neighbour of its match nn(i).
        k: neighbours listed per row before the exact fallback search.

    Returns:
        Matches with score d1 / d_fginn, ascending.
    """
    if not 0 < ratio <= 1:
        raise ConfigError(f"ratio must be in (0, 1], got {ratio}")
    if desc0.shape[0] == 0 or desc1.shape[0] == 0:
        return Matches.empty()
    xy1 = torch.as_tensor(xy1, device=desc1.device).float()
    dist, idx, _, col_idx = knn(desc0, desc1, k, 1 if mutual else 0, block_size)
    second = nearest_far(desc0, desc1, xy1, xy1[idx[:, 0]], spatial_radius, dist, idx, block_size)
    score = _ratio(dist[:, 0], second)
    ok = score < ratio
    if mutual:
        ok &= col_idx[idx[:, 0], 0] == torch.arange(desc0.shape[0], device=idx.device)
    keep = torch.nonzero(ok).flatten()
    return _to_matches(keep, idx[keep, 0], score[keep])


def _ratio(first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
    """first / second with 0 / 0 = 1 (ambiguous) and x / inf = 0."""
    out = first / second
    return torch.where((first == 0) & (second == 0), torch.ones_like(out), out)
