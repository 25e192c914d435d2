"""Skeleton of the free space (mrslam_env.merge.skeleton): Zhang–Suen thinning against the
paper's removal conditions, edge cases, pruning, the graph, and a realistic map."""

from __future__ import annotations

import numpy as np
import pytest
from merge_fixtures import map_pair
from scipy import ndimage

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.skeleton import (
    NODE_END,
    NODE_JUNCTION,
    NODE_LOOP,
    SkeletonConfig,
    clean_free_space,
    free_space_graph,
    prune_spurs,
    skeleton_graph,
    skeletonize_free_space,
    thin_to_eight_connected,
    zhang_suen_thinning,
)

# p2..p9 clockwise from north; north is row + 1 (row 0 is the lowest y).
RING = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)]


def removable(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels satisfying the paper's thinning condition 1 and condition 2 (slow, obvious)."""
    padded = np.pad(image.astype(int), 1)
    first = np.zeros(image.shape, dtype=bool)
    second = np.zeros(image.shape, dtype=bool)
    for r, c in np.argwhere(image):
        p2, p3, p4, p5, p6, p7, p8, p9 = (padded[r + 1 + dr, c + 1 + dc] for dr, dc in RING)
        ring = [p2, p3, p4, p5, p6, p7, p8, p9]
        n = sum(ring)
        s = sum(ring[i] == 0 and ring[(i + 1) % 8] == 1 for i in range(8))
        if not (2 <= n <= 6 and s == 1):
            continue
        first[r, c] = p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0
        second[r, c] = p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0
    return first, second


def grid_of(free: np.ndarray, resolution: float = 0.05) -> GridMap:
    cells = np.where(free, FREE, OCCUPIED).astype(np.int8)
    return GridMap(cells=cells, resolution=resolution)


def random_blobs(seed: int, shape=(50, 60)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    mask = ndimage.binary_opening(rng.random(shape) < 0.62)
    return ndimage.binary_closing(mask)


@pytest.mark.parametrize("seed", range(6))
def test_thinning_leaves_no_pixel_the_paper_would_remove(seed):
    mask = random_blobs(seed)
    skeleton = zhang_suen_thinning(mask)
    first, second = removable(skeleton)
    assert not first.any() and not second.any()
    assert np.array_equal(zhang_suen_thinning(skeleton), skeleton)  # fixed point
    assert not (skeleton & ~mask).any()
    # Thinning keeps every 8-connected component (ZS only loses 2x2 squares, not present).
    _, before = ndimage.label(mask, structure=np.ones((3, 3)))
    _, after = ndimage.label(skeleton, structure=np.ones((3, 3)))
    assert after == before


def test_realistic_map_skeleton_is_a_fixed_point_inside_free_space():
    m1, _ = map_pair("office", (5, 4), (9, 4), np.array([1.0, 2.0, 1.2]))
    skeleton = skeletonize_free_space(m1)
    first, second = removable(skeleton)
    assert skeleton.sum() > 200
    assert not first.any() and not second.any()
    assert clean_free_space(m1)[skeleton].all()  # filled specks count as free
    assert m1.free[skeleton].mean() > 0.98


def test_edge_cases_empty_single_pixel_and_already_thin():
    assert not zhang_suen_thinning(np.zeros((5, 5), dtype=bool)).any()
    single = np.zeros((5, 5), dtype=bool)
    single[2, 2] = True
    assert np.array_equal(zhang_suen_thinning(single), single)
    line = np.zeros((9, 12), dtype=bool)
    line[4, 1:11] = True
    line[5:8, 10] = True
    assert np.array_equal(zhang_suen_thinning(line), line)
    unknown = GridMap(cells=np.full((10, 10), UNKNOWN, dtype=np.int8), resolution=0.05)
    assert not skeletonize_free_space(unknown).any()


def test_inputs_are_not_mutated():
    mask = random_blobs(1)
    copy = mask.copy()
    zhang_suen_thinning(mask)
    assert np.array_equal(mask, copy)
    grid = grid_of(mask)
    cells = grid.cells.copy()
    skeleton = skeletonize_free_space(grid)
    assert np.array_equal(grid.cells, cells)
    before = skeleton.copy()
    prune_spurs(skeleton, 5)
    skeleton_graph(skeleton)
    assert np.array_equal(skeleton, before)


def test_corridor_skeleton_runs_down_its_middle():
    free = np.zeros((40, 220), dtype=bool)
    free[10:30, 5:215] = True  # rows 10..29: the middle lies between rows 19 and 20
    grid = grid_of(free)
    skeleton = prune_spurs(skeletonize_free_space(grid), min_length=12)
    rows = np.argwhere(skeleton[:, 30:190])[:, 0]
    assert len(rows) >= 160
    assert np.all(np.abs(rows - 19.5) <= 1.0)
    graph = skeleton_graph(skeleton)
    assert len(graph.edges) == 1
    assert graph.edges[0].length > 180


def test_clearance_keeps_the_skeleton_away_from_walls():
    free = np.zeros((60, 60), dtype=bool)
    free[5:55, 5:55] = True
    skeleton = skeletonize_free_space(grid_of(free), clearance=0.5)
    distance = ndimage.distance_transform_edt(free) * 0.05
    assert skeleton.any()
    assert distance[skeleton].min() >= 0.5


def test_specks_in_free_space_make_no_skeleton_loops():
    free = np.zeros((60, 80), dtype=bool)
    free[5:55, 5:75] = True
    cells = np.where(free, FREE, OCCUPIED).astype(np.int8)
    rng = np.random.default_rng(3)
    specks = rng.integers([10, 10], [50, 70], size=(12, 2))
    cells[specks[:, 0], specks[:, 1]] = UNKNOWN
    cells[specks[:6, 0] + 1, specks[:6, 1]] = OCCUPIED
    grid = GridMap(cells=cells, resolution=0.05)
    assert clean_free_space(grid)[specks[:, 0], specks[:, 1]].all()
    graph = free_space_graph(grid)
    # A tree: one component, edges = nodes - 1, no loop node.
    assert len(graph.edges) == len(graph.nodes) - 1
    assert NODE_LOOP not in graph.node_kinds


def test_prune_spurs_removes_short_branches_only():
    image = np.zeros((30, 60), dtype=bool)
    image[15, 5:55] = True  # main line
    image[16:20, 30] = True  # spur of 4 cells
    image[1:15, 45] = True  # long branch of 14 cells
    pruned = prune_spurs(image, min_length=8)
    assert not pruned[17:20, 30].any()  # (16, 30) may stay as the junction pixel
    assert not (pruned & ~image).any()
    assert pruned[15, 5] and pruned[15, 54] and pruned[1, 45]  # the three ends
    assert pruned[15].sum() >= 47 and pruned[2:14, 45].all()
    _, components = ndimage.label(pruned, structure=np.ones((3, 3)))
    assert components == 1
    graph = skeleton_graph(pruned)
    assert sorted(graph.node_kinds.tolist()) == [NODE_END, NODE_END, NODE_END, NODE_JUNCTION]
    # Whole short components go as well.
    lonely = np.zeros((10, 10), dtype=bool)
    lonely[5, 2:5] = True
    assert not prune_spurs(lonely, min_length=5).any()
    with pytest.raises(ValueError, match="min_length"):
        prune_spurs(image, -1.0)


def test_graph_of_a_t_and_of_a_ring():
    tee = np.zeros((20, 30), dtype=bool)
    tee[10, 2:28] = True
    tee[11:18, 15] = True
    graph = skeleton_graph(tee)
    assert sorted(graph.node_kinds.tolist()) == [NODE_END] * 3 + [NODE_JUNCTION]
    assert len(graph.edges) == 3
    assert graph.total_length == pytest.approx(25 + 7, abs=2.5)
    for edge in graph.edges:  # ordered, 8-connected, between its nodes
        steps = np.abs(np.diff(edge.cells, axis=0))
        assert steps.max() <= 1 and (steps.sum(axis=1) >= 1).all()
        assert tee[edge.cells[:, 0], edge.cells[:, 1]].all()

    ring = np.zeros((20, 20), dtype=bool)
    ring[4, 4:16] = ring[15, 4:16] = ring[4:16, 4] = ring[4:16, 15] = True
    graph = skeleton_graph(ring)
    assert graph.node_kinds.tolist() == [NODE_LOOP]
    assert len(graph.edges) == 1
    edge = graph.edges[0]
    assert edge.start == edge.end
    assert np.array_equal(edge.cells[0], edge.cells[-1])
    assert len(np.unique(edge.cells, axis=0)) == graph.skeleton.sum()


def test_thin_to_eight_connected_removes_staircase_corners():
    stairs = np.zeros((10, 10), dtype=bool)
    for k in range(4):
        stairs[2 + k, 2 + k] = stairs[2 + k, 3 + k] = True
    thin = thin_to_eight_connected(stairs)
    assert thin.sum() < stairs.sum()
    assert thin[2, 2] and thin[5, 6]  # both ends survive
    assert (ndimage.convolve(thin.astype(int), np.ones((3, 3)), mode="constant")[thin] <= 3).all()
    _, components = ndimage.label(thin, structure=np.ones((3, 3)))
    assert components == 1


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match=r"SkeletonConfig\.clearance"):
        SkeletonConfig(clearance=-0.1)
    with pytest.raises(ValueError, match=r"SkeletonConfig\.min_spur_length"):
        SkeletonConfig(min_spur_length=float("nan"))


def _reference_edges(thin: np.ndarray, node_of: np.ndarray) -> list[tuple[int, int, list]]:
    """The branch tracing of :func:`skeleton_graph` in plain Python (the numba kernel's
    reference): (start node, end node, cells) per edge, then the loop nodes' pixels."""
    from mrslam_env.merge.skeleton import _RING

    rows, cols = thin.shape
    node_of = node_of.copy()
    next_node = int(node_of.max(initial=-1)) + 1

    def neighbours(r: int, c: int) -> list[tuple[int, int]]:
        return [
            (r + int(dr), c + int(dc))
            for dr, dc in _RING
            if 0 <= r + dr < rows and 0 <= c + dc < cols and thin[r + dr, c + dc]
        ]

    visited = np.zeros(thin.shape, dtype=bool)
    edges: list[tuple[int, int, list]] = []
    seen: set = set()

    def trace(start: tuple[int, int], first: tuple[int, int]) -> None:
        path, prev, cur = [start, first], start, first
        while node_of[cur] < 0:
            visited[cur] = True
            following = [p for p in neighbours(*cur) if p != prev]
            if not following:
                break
            prev, cur = cur, following[0]
            path.append(cur)
            if cur == start:
                break
        end = int(node_of[cur]) if node_of[cur] >= 0 else int(node_of[start])
        edges.append((int(node_of[start]), end, path))

    for r, c in np.argwhere(node_of >= 0):
        start = (int(r), int(c))
        for nb in neighbours(*start):
            if node_of[nb] >= 0:
                key = (min(start, nb), max(start, nb))
                if node_of[nb] == node_of[start] or key in seen:
                    continue
                seen.add(key)
                edges.append((int(node_of[start]), int(node_of[nb]), [start, nb]))
            elif not visited[nb]:
                trace(start, nb)
    for r, c in np.argwhere(thin & ~visited & (node_of < 0)):
        if visited[r, c]:
            continue
        start = (int(r), int(c))
        node_of[start] = next_node
        next_node += 1
        visited[start] = True
        trace(start, neighbours(*start)[0])
    return edges


def test_the_numba_branch_tracer_matches_the_python_reference(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``skeleton_graph`` traces branches in numba (``_trace_edges``); on random
    skeletons and a closed loop without nodes it gives the reference's edges exactly."""
    from mrslam_env.merge import skeleton as module

    calls = []
    kernel = module._trace_edges

    def spy(thin: np.ndarray, node_of: np.ndarray, count: int) -> tuple:
        before = node_of.copy()
        out = kernel(thin, node_of, count)
        calls.append((thin.copy(), before, out))
        return out

    monkeypatch.setattr(module, "_trace_edges", spy)
    rng = np.random.default_rng(0)
    loop = np.zeros((30, 30), dtype=bool)
    loop[5, 5:21] = loop[20, 5:21] = loop[5:21, 5] = loop[5:21, 20] = True
    cases = [loop] + [
        rng.random((int(rng.integers(5, 50)), int(rng.integers(5, 50)))) < density
        for density in (0.05, 0.2, 0.4)
        for _ in range(10)
    ]
    for skeleton in cases:
        module.skeleton_graph(skeleton)
    assert len(calls) == len(cases)
    loops_seen = 0
    for thin, node_of, (starts, ends, offsets, cells, loops) in calls:
        expected = _reference_edges(thin, node_of)
        assert len(expected) == len(starts)
        for k, (start, end, path) in enumerate(expected):
            assert (starts[k], ends[k]) == (start, end)
            assert np.array_equal(cells[offsets[k] : offsets[k + 1]], np.array(path))
        loops_seen += len(loops)
    assert loops_seen >= 1  # the closed loop without nodes was opened
