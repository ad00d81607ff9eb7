"""Plane selection (Secs. 3.5-3.7): tile sets -> H* -> H -> M+ -> F-bar -> fused F^{l*} -> F^theta."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .blocks import Block
from .consensus import epipolar_consensus
from .epipolar_vote import PairFundamentals, epipolar_consistency
from .fusion import fuse_planes, global_orientation_filter, greedy_two_per_tile, plane_groups
from .match_table import MatchTable
from .tile_sets import TileConfig, TileSets, best_sets_per_tile, best_sets_per_tile_pair, tile_sets

__all__ = ["PlaneSelection", "select_planes"]


@dataclass
class PlaneSelection:
    """The sets of Secs. 3.5-3.7, each a :class:`~.tile_sets.TileSets` over the match table.

    Attributes:
        sets: every tile set H^l_v; superset: H (the best per tile pair, then per tile).
        keep: (M,) bool, the matches of M+ (the epipolar vote).
        fbar: F-bar; fused: F^{l*} (F-bar's sets fused with their near copies); ftheta: F^theta (the fused
            sets that agree with the global orientation).
        theta: (S,) each F^theta set's orientation, radians; theta_plus: the global orientation, radians.
        vote: the rule that chose M+ ("paper" or "consensus"), and why (``vote_reason``).
        vote_planes: distinct homographies in the chosen M+.
    """

    sets: TileSets
    superset: TileSets
    keep: np.ndarray
    fbar: TileSets
    fused: TileSets
    ftheta: TileSets
    theta: np.ndarray
    theta_plus: float
    vote: str
    vote_reason: str
    vote_planes: int

    @property
    def counts(self) -> dict[str, int]:
        return {"tile_sets": len(self.sets), "superset_H": len(self.superset), "epipolar_kept": int(self.keep.sum()),
                "epipolar_planes": self.vote_planes,
                "fbar_sets": len(self.fbar), "ftheta_sets": len(self.ftheta),
                "ftheta_matches": int(self.ftheta.union().sum())}

    def arrays(self) -> dict[str, np.ndarray]:
        """The selected sets (CSR arrays per set family) and orientations, for ``--save-stages``."""
        out = {"epipolar_keep": self.keep, "ftheta_theta": self.theta, "theta_plus": np.array(self.theta_plus)}
        for name in ("superset", "fbar", "ftheta"):
            sets = getattr(self, name)
            out.update({f"{name}_plane": sets.plane, f"{name}_tile0": sets.tile0, f"{name}_tile1": sets.tile1,
                        f"{name}_indptr": sets.indptr, f"{name}_indices": sets.indices})
        return out


def select_planes(table: MatchTable, expanded: sp.csr_matrix, tiles0: list[Block], tiles1: list[Block],
                  config: TileConfig, threads: int = 1) -> PlaneSelection:
    """Secs. 3.5-3.7 on the plane memberships ``expanded`` (L, M) of Sec. 3.4 (the epipolar vote in
    ``threads`` threads: the same result for any number)."""
    w = table.weight
    sets = tile_sets(table, expanded, tiles0, tiles1)
    star = sets.subset(best_sets_per_tile_pair(sets, w, q=config.q_pair))
    superset = star.subset(best_sets_per_tile(star, w, q=config.q_tile))
    keep, vote, reason, n_planes = _epipolar_selection(table, superset, config, threads)
    filtered = superset.restrict(keep)
    groups = None if config.same_homography == "set" else plane_groups(filtered, config.t_ov,
                                                                         config.same_homography)
    fbar = filtered.subset(greedy_two_per_tile(filtered, w, t_ov=config.t_ov, groups=groups))
    fused = fuse_planes(sets.restrict(keep), fbar, w, t_ov=config.t_ov)
    ok, theta, theta_plus = global_orientation_filter(table, fused, bins=config.bins,
                                                      t_theta_plus=config.t_theta_plus)
    return PlaneSelection(sets, superset, keep, fbar, fused, fused.subset(ok), theta[ok], theta_plus, vote, reason,
                          n_planes)


def _homographies(sets: TileSets, keep: np.ndarray, t_ov: float) -> int:
    """Distinct homographies (``plane_groups``) among the sets of ``sets`` holding a match of ``keep`` (M,)."""
    held = sets.restrict(keep)
    held = held.subset(np.flatnonzero(np.diff(held.indptr) > 0))
    return len(np.unique(plane_groups(held, t_ov)[held.plane])) if len(held) else 0


def _epipolar_selection(table: MatchTable, superset: TileSets, config: TileConfig, threads: int
                        ) -> tuple[np.ndarray, str, str, int]:
    """M+ (M,) bool by ``config.vote``, the rule that decided, why, and the homographies it spans."""
    pairs = PairFundamentals(table, superset) if len(superset) >= 2 else None
    keep = epipolar_consistency(table, superset, t_perp=config.t_perp, t_xi=config.t_xi, min_union=config.min_union,
                                chunk=config.chunk, threads=threads, pairs=pairs)
    n_planes = _homographies(superset, keep, config.t_ov)
    kept = (f"the paper's epipolar vote kept {int(keep.sum())} matches consistent with the epipolar geometry of "
            f"enough pairs of planes (M+), on {n_planes} planes")
    if config.vote == "paper":
        return keep, "paper", f"{kept} (the paper's vote was asked for: vote=paper)", n_planes
    if keep.sum() >= config.min_union:
        return keep, "paper", kept, n_planes
    found = epipolar_consensus(table, superset, t_perp=config.t_perp, min_union=config.min_union, t_ov=config.t_ov,
                               min_planes=config.min_planes, pairs=pairs)
    weak = f"{kept}: too few, {int(keep.sum())} < {config.min_union} (min_union)"
    if not found.keep.any():
        return keep, "paper", (f"{weak}, and no single epipolar geometry is shared by {config.min_planes} planes "
                               "(min_planes): the vote's matches are kept"), n_planes
    chosen = (f"the largest group of planes sharing one epipolar geometry has {found.planes} planes and "
              f"{int(found.keep.sum())} matches, and is kept (consensus vote)")
    return found.keep, "consensus", f"{weak}; {chosen}", found.planes
