"""Compiled loops of nearest-neighbour matching on CPU (numba): the k smallest entries of each row or column of
a distance block, Blob matching's shortlist and greedy acceptance, and the first far neighbour of
``nn.nearest_far``.

Blob matching runs hundreds of times per Slime image pair on a few hundred descriptors per side; in numpy and
torch its steps are many calls on small arrays and the call overhead dominates. Here each step is one pass.

Order: that of a stable ascending argsort (equal values go to the lowest index, NaN after every number).
When NaN entries leave a row (column) of a block with fewer than k NaN-free groups of the entries equal mod
8k, ``smallest_rows`` (``smallest_cols``) report that torch.topk must answer for the whole block instead,
as the bounded numpy search these kernels replace did (see ``_few_clean_groups``).
"""

from __future__ import annotations

import numpy as np

from .._runtime.compiled import kernel

_CHUNK = 16  # entries tested at once against a bound


@kernel
def _less(x, y):
    """x before y in ascending order with NaN last."""
    return x < y or (np.isnan(y) and not np.isnan(x))


@kernel
def _take(vals, idx, r, filled, x, j):
    """Offer value x of index j to the ascending list vals[r] (k,), idx[r] (k,) holding ``filled`` entries:
    inserted after the entries equal to it, the last entry dropping out when the list is full. Returns the
    new count."""
    k = vals.shape[1]
    if filled < k:
        p = filled
        filled += 1
    elif _less(x, vals[r, k - 1]):
        p = k - 1
    else:
        return filled
    while p > 0 and _less(x, vals[r, p - 1]):
        vals[r, p] = vals[r, p - 1]
        idx[r, p] = idx[r, p - 1]
        p -= 1
    vals[r, p] = x
    idx[r, p] = j
    return filled


@kernel
def _kth_smallest(low, k):
    """The k-th smallest non-NaN value of low (G,), NaN when there are fewer than k."""
    out = np.float32(np.nan)  # float32 unless low is float64
    for i in range(len(low)):
        x = low[i]
        count = np.int32(0)  # int32 counts vectorise
        for j in range(len(low)):
            count += np.int32(low[j] <= x)
        if count >= k and not out <= x:
            out = x
    return out


@kernel
def _few_clean_groups(line, k):
    """Whether a line (L,) with L > 8k has fewer than k NaN-free groups of the entries equal mod 8k: where the
    former search's bound (the k-th smallest group minimum) was NaN and torch.topk answered."""
    groups = 8 * k
    clean = 0
    for g in range(groups):
        ok = True
        for t in range(g, len(line), groups):
            if np.isnan(line[t]):
                ok = False
                break
        if ok:
            clean += 1
    return clean < k


@kernel
def smallest_rows(d, k):
    """The k <= M smallest entries of each row of d (B, M), ascending: values (B, k), column indices (B, k) and
    False where torch.topk must answer instead (rows with NaN entries, see ``_few_clean_groups``).

    Only the entries under a bound are ranked: the k-th smallest of the minima of 2k column groups (the
    columns equal mod 2k), each of which is an entry of the row; no bound (NaN) when M <= 2k or fewer than k
    groups are free of NaN. Loops run over slices from 0, which LLVM vectorises.
    """
    b, m = d.shape
    g = 2 * k
    vals = np.empty((b, k), d.dtype)
    idx = np.empty((b, k), np.int64)
    low = np.empty(g, d.dtype)
    if k == 0:
        return vals, idx, True
    for r in range(b):
        row = d[r]
        bound, has_nan = np.float32(np.nan), False  # NaN: no bound
        if g < m:
            low[:] = row[:g]
            for s in range(0, m, g):
                seg = row[s:s + g]
                for t in range(len(seg)):
                    x = seg[t]
                    has_nan |= np.isnan(x)
                    low[t] = min(low[t], x)  # x when x < low[t]: a group with a NaN may stay NaN, not counted
            bound = _kth_smallest(low, k)
        filled = 0
        for s in range(0, m, _CHUNK):
            seg = row[s:s + _CHUNK]
            hit = False
            for t in range(len(seg)):
                hit |= not seg[t] > bound
            if hit:
                for t in range(len(seg)):
                    if not seg[t] > bound:
                        filled = _take(vals, idx, r, filled, seg[t], s + t)
        if has_nan and 8 * k < m and _few_clean_groups(row, k):
            return vals, idx, False
    return vals, idx, True


@kernel
def smallest_cols(d, k):
    """``smallest_rows`` of d.T without transposing: the k <= B smallest entries of each column of d (B, M),
    ascending, with per-column bounds (over the rows equal mod 2k) and lists filled in passes over the rows:
    values (M, k), row indices (M, k), False where torch.topk must answer instead."""
    b, m = d.shape
    g = 2 * k
    vals = np.empty((m, k), d.dtype)
    idx = np.empty((m, k), np.int64)
    bound = np.full(m, np.nan, d.dtype)
    has_nan = np.zeros(m, np.bool_)
    if k == 0:
        return vals, idx, True
    if g < b:
        low = d[:g].copy()  # (g, M)
        for r in range(b):
            row, low_r = d[r], low[r % g]
            for c in range(m):
                x = row[c]
                has_nan[c] |= np.isnan(x)
                low_r[c] = min(low_r[c], x)
        count = np.empty(m, np.int32)
        for i in range(g):  # bound[c]: the k-th smallest non-NaN low[:, c], as ``_kth_smallest``
            count[:] = 0
            low_i = low[i]
            for j in range(g):
                low_j = low[j]
                for c in range(m):
                    count[c] += np.int32(low_j[c] <= low_i[c])
            for c in range(m):
                if count[c] >= k and not bound[c] <= low_i[c]:
                    bound[c] = low_i[c]
    filled = np.zeros(m, np.int64)
    for r in range(b):
        row = d[r]
        for s in range(0, m, _CHUNK):
            seg, seg_bound = row[s:s + _CHUNK], bound[s:s + _CHUNK]
            hit = False
            for t in range(len(seg)):
                hit |= not seg[t] > seg_bound[t]
            if hit:
                for t in range(len(seg)):
                    if not seg[t] > seg_bound[t]:
                        filled[s + t] = _take(vals, idx, s + t, filled[s + t], seg[t], r)
    if 8 * k < b:
        for c in range(m):
            if has_nan[c] and _few_clean_groups(d[:, c], k):
                return vals, idx, False
    return vals, idx, True


@kernel
def shortlist(row_dist, row_idx, col_idx):
    """Blob matching's shortlist: the pairs (i, j = row_idx[i, r]) with i in col_idx[j], in row-major order.

    Args:
        row_dist, row_idx: (N, kr) each row's nearest columns; col_idx: (M, kc) each column's nearest rows.

    Returns:
        i (P,), j (P,) and their distances v (P,).
    """
    n, kr = row_idx.shape
    i = np.empty(n * kr, np.int64)
    j = np.empty(n * kr, np.int64)
    v = np.empty(n * kr, row_dist.dtype)
    p = 0
    for a in range(n):
        for r in range(kr):
            b = row_idx[a, r]
            for c in range(col_idx.shape[1]):
                if col_idx[b, c] == a:
                    i[p], j[p], v[p] = a, b, row_dist[a, r]
                    p += 1
                    break
    return i[:p], j[:p], v[:p]


@kernel
def greedy_accept(rows, cols, order, max_per):
    """(P,) bool: walk the pairs (rows[q], cols[q]) (P,) in ``order`` (P,) and accept each while its row and
    its column hold fewer than ``max_per`` accepted pairs."""
    n_rows = n_cols = 0
    for q in range(len(rows)):
        n_rows, n_cols = max(n_rows, rows[q] + 1), max(n_cols, cols[q] + 1)
    row_left = np.full(n_rows, max_per, np.int64)
    col_left = np.full(n_cols, max_per, np.int64)
    accepted = np.zeros(len(rows), np.bool_)
    for q in order:
        a, b = rows[q], cols[q]
        if row_left[a] > 0 and col_left[b] > 0:
            row_left[a] -= 1
            col_left[b] -= 1
            accepted[q] = True
    return accepted


@kernel
def first_far(nn_dist, nn_idx, rows, xy, anchor, r2):
    """Distance to the first entry of ascending k-NN lists located farther than sqrt(r2) from an anchor.

    Args:
        nn_dist, nn_idx: (N, k) ascending distances / indices into xy (M, 2) of N lists; rows: (P,) the list
            of each query; anchor: (P, 2); r2: squared radius, of the dtype the test runs in.

    Returns:
        (P,) float32 distances, inf where no entry is far; (R,) the queries where no entry is far.
    """
    p, k = len(rows), nn_idx.shape[1]
    out = np.full(p, np.inf, np.float32)
    rest = np.empty(p, np.int64)
    n_rest = 0
    for q in range(p):
        a = rows[q]
        found = False
        for r in range(k):
            c = nn_idx[a, r]
            dx = xy[c, 0] - anchor[q, 0]
            dy = xy[c, 1] - anchor[q, 1]
            if dx * dx + dy * dy > r2:
                out[q] = nn_dist[a, r]
                found = True
                break
        if not found:
            rest[n_rest] = q
            n_rest += 1
    return out, rest[:n_rest]
