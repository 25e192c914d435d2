"""Joint refinement of N map frames (mrslam_env.merge.graph).

The pose graph on its own (synthetic edges): exact edges give back the truth from a poor
start; with noisy edges the joint solution is closer to the truth than the chain of the
same edges, and it closes a cycle the chain leaves open; the fixed node stays put, a node
no edge reaches keeps its estimate. With maps: three partial maps of the office whose
chained estimate is off by a few decimetres come out within a few centimetres.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import corridor_maps

from mrslam_env.geometry import compose, inverse, wrap_angle
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.merge.graph import (
    GraphEdge,
    JointRefineConfig,
    graph_residuals,
    refine_jointly,
    solve_pose_graph,
    wall_information,
)

TRUTH = np.array([[0.0, 0.0, 0.0], [4.0, 1.0, 0.5], [2.0, 5.0, -1.0], [-3.0, 4.0, 2.5]])


def edge(truth: np.ndarray, i: int, j: int, noise=(0.0, 0.0, 0.0), weight=1.0) -> GraphEdge:
    relative = compose(inverse(truth[i]), truth[j]) + np.asarray(noise)
    return GraphEdge(i=i, j=j, mapi_from_mapj=relative, weight=weight, pivot=np.array([1.0, 1.0]))


def errors(pose: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (rad) errors."""
    return float(np.hypot(*(pose[:2] - truth[:2]))), abs(float(wrap_angle(pose[2] - truth[2])))


def chain(edges: list[GraphEdge], n: int) -> list[np.ndarray]:
    """The poses composed along a chain of edges 0-1, 1-2, ... (blindly)."""
    poses = [np.zeros(3)]
    for k in range(1, n):
        e = next(e for e in edges if (e.i, e.j) == (k - 1, k))
        poses.append(compose(poses[-1], e.mapi_from_mapj))
    return poses


def test_exact_edges_give_the_truth_from_a_poor_start() -> None:
    edges = [edge(TRUTH, i, j) for i, j in ((0, 1), (1, 2), (0, 2), (2, 3), (1, 3))]
    start = TRUTH + np.array([0.0, 0.0, 0.0]) + np.array([[0, 0, 0], [0.5, -0.4, 0.1]] * 2)
    solved = solve_pose_graph(start, edges, fixed=0)
    for pose, truth in zip(solved, TRUTH, strict=True):
        moved, turned = errors(pose, truth)
        assert moved < 1e-6 and turned < 1e-8
    assert np.abs(graph_residuals(edges, solved)).max() < 1e-6


def test_the_joint_solution_beats_the_chain_and_closes_the_cycle() -> None:
    truth = TRUTH[:3]
    rng = np.random.default_rng(0)
    joint_worse = 0
    chain_total = joint_total = 0.0
    for _ in range(20):
        noise = [rng.normal(0.0, [0.05, 0.05, math.radians(1.0)]) for _ in range(3)]
        edges = [
            edge(truth, i, j, n) for (i, j), n in zip(((0, 1), (1, 2), (0, 2)), noise, strict=True)
        ]
        chained = chain(edges, 3)
        solved = solve_pose_graph(chained, edges, fixed=0)
        chain_error = sum(errors(p, t)[0] for p, t in zip(chained, truth, strict=True))
        joint_error = sum(errors(p, t)[0] for p, t in zip(solved, truth, strict=True))
        chain_total += chain_error
        joint_total += joint_error
        joint_worse += joint_error > chain_error
        # The chain leaves the cycle's misfit on the edge it ignores; the joint solution
        # spreads it: its worst residual is smaller than the chain's.
        assert (
            np.abs(graph_residuals(edges, solved)).max()
            < np.abs(graph_residuals(edges, chained)).max()
        )
    assert joint_total < 0.8 * chain_total
    assert joint_worse <= 4


def test_a_heavier_edge_is_followed_more_closely() -> None:
    truth = TRUTH[:3]
    noise = (0.2, 0.0, 0.0)
    light = [edge(truth, 0, 1), edge(truth, 1, 2), edge(truth, 0, 2, noise, weight=1.0)]
    heavy = [edge(truth, 0, 1), edge(truth, 1, 2), edge(truth, 0, 2, noise, weight=25.0)]
    solved_light = solve_pose_graph(truth, light)
    solved_heavy = solve_pose_graph(truth, heavy)
    assert errors(solved_heavy[2], truth[2])[0] > errors(solved_light[2], truth[2])[0]


def test_the_fixed_node_stays_and_an_unreached_node_keeps_its_estimate() -> None:
    start = TRUTH + np.array([0.3, -0.2, 0.05])
    edges = [edge(TRUTH, 1, 2), edge(TRUTH, 2, 1)]
    solved = solve_pose_graph(start, edges, fixed=1)
    np.testing.assert_allclose(solved[1], start[1])
    np.testing.assert_allclose(solved[0], start[0])
    np.testing.assert_allclose(solved[3], start[3])
    relative = compose(inverse(solved[1]), solved[2])
    np.testing.assert_allclose(relative, compose(inverse(TRUTH[1]), TRUTH[2]), atol=1e-6)


def test_no_edges_change_nothing() -> None:
    solved = solve_pose_graph(TRUTH, [])
    np.testing.assert_allclose(np.array(solved), TRUTH)


@pytest.mark.parametrize(
    ("edges", "fixed", "message"),
    [
        ([], 4, "fixed must be"),
        ([GraphEdge(0, 0, np.zeros(3), 1.0, np.zeros(2))], 0, "not between two"),
        ([GraphEdge(0, 5, np.zeros(3), 1.0, np.zeros(2))], 0, "not between two"),
        ([GraphEdge(0, 1, np.zeros(3), 0.0, np.zeros(2))], 0, "weight > 0"),
    ],
)
def test_bad_graphs_are_refused(edges: list[GraphEdge], fixed: int, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        solve_pose_graph(TRUTH, edges, fixed=fixed)


def test_a_corridor_pins_across_its_walls_and_a_corner_both_ways() -> None:
    cells = np.full((40, 200), FREE, dtype=np.int8)
    cells[[5, 35], :] = OCCUPIED  # two walls along x, 1.5 m apart
    corridor = GridMap(cells=cells, resolution=0.05)
    pivot = np.array([5.0, 1.0])
    information = wall_information(corridor, corridor, np.zeros(3), pivot)
    assert information[0, 0] == pytest.approx(0.0, abs=1e-6)  # along: nothing
    assert information[1, 1] == pytest.approx(400.0, rel=0.01)  # across: every wall cell
    assert information[2, 2] > 0  # the walls' length resists a turn
    cells = cells.copy()
    cells[:, 100] = OCCUPIED  # a cross wall
    crossed = GridMap(cells=cells, resolution=0.05)
    information = wall_information(crossed, crossed, np.zeros(3), pivot)
    assert information[0, 0] > 30 and np.all(np.linalg.eigvalsh(information) > 1)
    # Map j shifted off map i by more than a cell along y shares no wall.
    apart = wall_information(corridor, corridor, np.array([0.0, 0.3, 0.0]), pivot)
    assert not np.any(apart)


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="max_shift"):
        JointRefineConfig(max_shift=0.0)
    with pytest.raises(ValueError, match="min_acceptance_index"):
        JointRefineConfig(min_acceptance_index=1.5)


def test_three_office_maps_are_refined_jointly_closer_than_their_chain() -> None:
    # Three overlapping partial maps along the corridor, each in its own frame.
    maps, truth = corridor_maps()
    # The chain: each join a little off, the errors adding up along it.
    step_off = np.array([0.08, -0.06, math.radians(1.0)])
    chained = [truth[0], compose(truth[1], step_off)]
    chained.append(compose(chained[1], compose(compose(inverse(truth[1]), truth[2]), step_off)))
    result = refine_jointly(maps, chained, rng=np.random.default_rng(0))
    assert {(e.i, e.j) for e in result.edges} == {(0, 1), (1, 2), (0, 2)}
    np.testing.assert_allclose(result.transforms[0], truth[0])
    for k in (1, 2):
        moved, turned = errors(result.transforms[k], truth[k])
        chain_moved, _ = errors(chained[k], truth[k])
        assert moved < 0.05 and turned < math.radians(0.5), (k, moved, math.degrees(turned))
        assert moved < chain_moved
