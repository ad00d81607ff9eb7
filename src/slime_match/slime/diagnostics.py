"""What Slime tells its user about a run: layouts that make it slow, and which stage left no match and why."""

from __future__ import annotations

from .tile_sets import TileConfig

__all__ = ["empty_result_reason", "layout_warning", "tile_count_warning"]

MANY_BLOCK_PAIRS = 4000  # 10x a 4:3 image pair's 400 at the paper's scales: warn, the run will be slow
MANY_TILES = 150  # tiles of one image: about 2048 x 1536 px (140), 12x a 640 x 480 image's


def layout_warning(n_blocks0: int, n_blocks1: int) -> str | None:
    """A warning when the images (elongated ones: blocks follow the shorter side) give very many block pairs."""
    if n_blocks0 * n_blocks1 <= MANY_BLOCK_PAIRS:
        return None
    return (f"{n_blocks0 * n_blocks1} block pairs ({n_blocks0} x {n_blocks1} blocks; a 4:3 pair has 400): blocks "
            "follow each image's shorter side, so an elongated image makes Slime slow and memory-hungry; "
            "fewer block scales (--scales 1,2) or the base pipeline alone (--method hz+) are much faster")


def tile_count_warning(n_tiles0: int, n_tiles1: int) -> str | None:
    """A warning when an image is so large that its full-resolution tiles make Slime slow (Secs. 3.5-3.8)."""
    if max(n_tiles0, n_tiles1) <= MANY_TILES:
        return None
    return (f"{n_tiles0} and {n_tiles1} tiles of 256 px (a 640x480 image has 12): the tiles, the base pipeline run "
            "on them and the tile match sets grow with the image size, so Slime gets slow and memory-hungry; "
            "--max-side 1200 (max_side=1200, Slime's default) shrinks the images before matching and maps the "
            "matches back")


def empty_result_reason(counts: dict[str, int], tiles: TileConfig) -> str:
    """Which stage left no match, and why (paper Secs. 3.2-3.8), from the stage counts of ``run_slime``."""
    if counts["block_planes"] == 0:
        return ("no block pair gave a plane (no homography with enough inliers, Secs. 3.2-3.3): the base "
                "pipeline found too few consistent matches between any two blocks")
    n_sets = counts["superset_H"]
    if counts["epipolar_kept"] == 0:
        consensus = (f", and no single epipolar geometry is shared by {tiles.min_planes} planes (the consensus "
                     "vote)" if tiles.vote == "consensus" else "")
        if n_sets * (n_sets - 1) <= tiles.t_xi * n_sets:
            return (f"the epipolar vote (Sec. 3.6) cannot keep a match with only {n_sets} tile match sets: a match "
                    f"must agree with more than {tiles.t_xi:g} x {n_sets} (t_xi |H|) of the "
                    f"{n_sets * (n_sets - 1)} epipolar geometries (fundamental matrices) of pairs of sets"
                    f"{consensus}; small images (few tiles: --min-side upsamples them) or scenes with few planes end "
                    "here; the base pipeline alone (--method hz+) may still match them")
        return (f"no match agreed with the epipolar geometries (fundamental matrices) of enough pairs of the "
                f"{n_sets} tile match sets (Sec. 3.6){consensus}: the planes found do not share one epipolar "
                "geometry")
    if counts["ftheta_matches"] == 0:
        return ("no tile match set survived the fusion of near-identical planes and the filter on the images' "
                "global relative orientation (Sec. 3.7)")
    return (f"the final global filter (DTM, Sec. 3.8) kept none of the {counts['ftheta_matches']} plane matches and "
            f"{counts['tile_matches']} tile matches")
