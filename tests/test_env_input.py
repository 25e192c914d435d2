"""Bad input to the env: one clear ValueError that names the agent or argument and the value."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_env.env import MultiRobotSlamEnv, checked_seed


@pytest.fixture(scope="module")
def env() -> MultiRobotSlamEnv:
    environment = MultiRobotSlamEnv("office", config=None)
    environment.reset(seed=0)
    return environment


@pytest.mark.parametrize(
    ("action", "kind"),
    [
        (np.array([True, False]), "bool"),
        (np.array([0.5 + 0j, 0.0]), "complex128"),
        (["0.5", "0.1"], "<U3"),
        ([0.5, "x"], "<U"),
        (np.array([0.5, None], dtype=object), "object"),
    ],
)
def test_actions_must_be_real_numbers(env: MultiRobotSlamEnv, action, kind: str) -> None:
    with pytest.raises(ValueError, match=rf"action for robot_0 must be real numbers, got {kind}"):
        env.step({"robot_0": action, "robot_1": np.zeros(2)})


@pytest.mark.parametrize("action", [np.array([1, 0], dtype=np.int32), [1, 0], (0.5, -0.5)])
def test_integer_and_float_actions_are_accepted(env: MultiRobotSlamEnv, action) -> None:
    env.step({"robot_0": action, "robot_1": np.zeros(2, dtype=np.float32)})


@pytest.mark.parametrize("seed", [-1, 1.5, True, "3", np.float64(2.0)])
def test_bad_seeds_name_the_value(seed) -> None:
    with pytest.raises(ValueError, match=r"seed must be a non-negative integer or None, got"):
        checked_seed(seed)
    with pytest.raises(ValueError, match=r"seed must be a non-negative integer"):
        MultiRobotSlamEnv("office", seed=seed)


def test_numpy_integer_seeds_give_the_same_episode_as_ints() -> None:
    first = MultiRobotSlamEnv("office")
    second = MultiRobotSlamEnv("office")
    observations, _ = first.reset(seed=7)
    same, _ = second.reset(seed=np.int64(7))
    assert checked_seed(np.uint8(7)) == 7 and type(checked_seed(np.int64(7))) is int
    np.testing.assert_array_equal(observations["robot_1"]["scan"], same["robot_1"]["scan"])
    with pytest.raises(ValueError, match=r"got -2"):
        first.reset(seed=-2)


@pytest.mark.parametrize("scenario", [None, 3, ["office"]])
def test_scenario_must_be_a_name_or_a_world(scenario) -> None:
    with pytest.raises(ValueError, match=r"scenario must be a scenario name or a WorldSpec"):
        MultiRobotSlamEnv(scenario)  # type: ignore[arg-type]
