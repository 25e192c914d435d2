"""Merging N maps into the first one's frame (as m-explore's map merge does for N robots).

Every pair of maps is merged with :func:`~mrslam_env.merge.pipeline.merge_maps`; the
confident answers are the edges of a graph whose nodes are the maps. Each map joins the
first map's frame along the tree of the best edges (a maximum spanning tree by merge score,
grown from map 0, Prim's rule), its transform the composition of the edges on its path. A
map that no confident edge reaches is listed as unmerged, never placed by a guess. An edge
left out of the tree that disagrees with the tree's composition (more than
``MultiMergeConfig.cycle_translation`` or ``cycle_rotation`` at the map's known centroid)
is reported: two confident answers that contradict each other mean one of them is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mrslam_env.geometry import compose, inverse, transform_points, wrap_scalar
from mrslam_env.gridmap import GridMap, crop_to_known
from mrslam_env.merge.fuse import fuse_all
from mrslam_env.merge.pipeline import KNOWN_MARGIN, MergeConfig, MergeResult, merge_maps
from mrslam_env.validation import check_fields

__all__ = ["MultiMergeConfig", "MultiMergeResult", "merge_many"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class MultiMergeConfig:
    """How N maps are merged."""

    merge: MergeConfig = field(default_factory=MergeConfig)
    """The pairwise merge."""
    cycle_translation: float = 0.5
    """An edge outside the tree disagrees with it beyond this, m (at m_j's centroid)."""
    cycle_rotation: float = math.radians(3.0)
    """... or beyond this turn, rad."""

    def __post_init__(self) -> None:
        check_fields(self, positive=("cycle_translation", "cycle_rotation"))


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MultiMergeResult:
    """The outcome of :func:`merge_many`.

    Attributes
    ----------
    transforms : list of ndarray (3,) or None
        ``map0_from_mapk`` per map (identity for map 0); None for an unmerged map.
    pairs : dict
        ``(i, j) -> MergeResult`` of every pairwise merge (``i < j``: ``mapi_from_mapj``).
    tree : list of (int, int)
        The edges the transforms compose along, parent first.
    inconsistent : list of (int, int)
        Confident edges outside the tree that contradict it.
    fused : GridMap
        Map 0 with every joined map fused in, on map 0's lattice at its resolution (with
        ``merge.crop_to_known``, the default, spanning their known areas).
    """

    transforms: list[FloatArray | None]
    pairs: dict[tuple[int, int], MergeResult]
    tree: list[tuple[int, int]]
    inconsistent: list[tuple[int, int]]
    fused: GridMap

    @property
    def unmerged(self) -> list[int]:
        return [k for k, t in enumerate(self.transforms) if t is None]


def _edge(pairs: dict[tuple[int, int], MergeResult], a: int, b: int) -> FloatArray | None:
    """``mapa_from_mapb`` from a confident pairwise merge, else None."""
    result = pairs[(min(a, b), max(a, b))]
    if result.transform is None:
        return None
    transform = np.asarray(result.transform, dtype=np.float64)
    return transform if a < b else inverse(transform)


def _score(result: MergeResult) -> float:
    return -math.inf if result.chosen is None else float(result.chosen.score)


def merge_many(
    maps: list[GridMap],
    config: MultiMergeConfig | None = None,
    *,
    rng: np.random.Generator | int | None = None,
) -> MultiMergeResult:
    """Merge N >= 2 maps into map 0's frame (module docstring).

    Parameters
    ----------
    maps : list of GridMap
        Each in its own frame.
    config : MultiMergeConfig, optional
    rng : numpy.random.Generator or int, optional
        The seed (a generator gives one draw); pair ``(i, j)`` is merged with the stream
        seeded by ``(seed, i, j)``. None: seed 0.

    Raises
    ------
    ValueError
        Fewer than two maps; :class:`~mrslam_env.merge.pipeline.MergeInputError` for a
        map that cannot be merged at all.
    """
    if len(maps) < 2:
        raise ValueError(f"merge_many needs at least 2 maps, got {len(maps)}")
    config = config if config is not None else MultiMergeConfig()
    seed = int(rng.integers(2**63)) if isinstance(rng, np.random.Generator) else (rng or 0)
    n = len(maps)
    # Each pair its own stream, seeded by (seed, i, j): a pair's answer does not depend on
    # the other maps or on the order the pairs are merged in.
    pairs = {
        (i, j): merge_maps(maps[i], maps[j], config.merge, rng=np.random.default_rng([seed, i, j]))
        for i in range(n)
        for j in range(i + 1, n)
    }
    transforms: list[FloatArray | None] = [None] * n
    transforms[0] = np.zeros(3)
    tree: list[tuple[int, int]] = []
    while True:  # Prim: the best confident edge from the joined maps to a new one
        options = [
            (_score(pairs[(min(a, b), max(a, b))]), a, b)
            for a in range(n)
            if transforms[a] is not None
            for b in range(n)
            if transforms[b] is None and _edge(pairs, a, b) is not None
        ]
        if not options:
            break
        _, parent, child = max(options)
        edge, base = _edge(pairs, parent, child), transforms[parent]
        assert edge is not None and base is not None
        transforms[child] = compose(base, edge)
        tree.append((parent, child))
    inconsistent = []
    in_tree = {frozenset(e) for e in tree}
    for i, j in pairs:
        ti, tj, edge = transforms[i], transforms[j], _edge(pairs, i, j)
        if frozenset((i, j)) in in_tree or ti is None or tj is None or edge is None:
            continue
        centroid = maps[j].cell_to_world(np.argwhere(~maps[j].unknown).mean(axis=0)[None, :])
        via_tree = transform_points(compose(inverse(ti), tj), centroid)[0]
        via_edge = transform_points(edge, centroid)[0]
        turn = abs(wrap_scalar(float(compose(inverse(ti), tj)[2] - edge[2])))
        if (
            math.hypot(*(via_tree - via_edge)) > config.cycle_translation
            or turn > config.cycle_rotation
        ):
            inconsistent.append((i, j))
    # As in merge_maps: with crop_to_known, the known parts are fused (unknown padding
    # neither widens the fused map nor costs memory).
    parts = [crop_to_known(m, KNOWN_MARGIN) if config.merge.crop_to_known else m for m in maps]
    fused = fuse_all(
        parts[0], ((parts[k], t) for k, t in enumerate(transforms) if k and t is not None)
    )
    return MultiMergeResult(
        transforms=transforms, pairs=pairs, tree=tree, inconsistent=inconsistent, fused=fused
    )
