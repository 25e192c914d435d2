"""Reset options are checked by name (issue 36), and one robot is a legitimate env: no
peers, the ``peer`` and ``comm`` parts of its observation sized for 0 teammates."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import replace
from types import MappingProxyType
from typing import Any

import gymnasium
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from agents.single_robot import SingleRobotEnv
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv, checked_options, parallel_env
from mrslam_env.wrappers import SINGLE_ROBOT_ID

SMALL = "tb3_sandbox"
FAST = EnvConfig(lidar=replace(EnvConfig().lidar, n_beams=90), max_cycles=20)


def test_a_misspelled_reset_option_is_refused_by_name_with_the_known_ones() -> None:
    env = parallel_env(scenario=SMALL, seed=0, config=FAST)
    with pytest.raises(ValueError, match="randomise_starts") as raised:
        env.reset(seed=0, options={"randomise_starts": True})
    message = str(raised.value)
    assert "\n" not in message
    for key in ("randomize_starts", "scenario"):
        assert key in message
    # The known keys still work, and an empty or absent options dict too.
    env.reset(seed=0, options={"randomize_starts": True, "scenario": SMALL})
    env.reset(seed=0, options={})
    env.reset(seed=0, options=None)


def test_any_mapping_is_accepted_as_options_and_checked_by_name_too() -> None:
    # dict(options) took any mapping before the names were checked: so does the check.
    for options in (
        MappingProxyType({"randomize_starts": True}),
        OrderedDict(randomize_starts=True),
    ):
        assert checked_options(options) == {"randomize_starts": True}
    assert checked_options(MappingProxyType({})) == {}
    with pytest.raises(ValueError, match="unknown reset option 'randomise_starts'"):
        checked_options(MappingProxyType({"randomise_starts": True}))
    with pytest.raises(ValueError, match="must be a mapping or None"):
        checked_options([("randomize_starts", True)])
    # And reset itself: a read-only mapping gives the same episode as the dict.
    env = parallel_env(scenario=SMALL, seed=0, config=FAST)
    from_dict, _ = env.reset(seed=4, options={"randomize_starts": True})
    # (reset is annotated dict, as PettingZoo's is; any mapping works.)
    proxy: Any = MappingProxyType({"randomize_starts": True})
    from_proxy, _ = env.reset(seed=4, options=proxy)
    assert from_proxy.keys() == from_dict.keys()
    for agent, observation in from_dict.items():
        for part, value in observation.items():
            np.testing.assert_array_equal(from_proxy[agent][part], value)


def test_the_single_robot_env_refuses_a_misspelled_option_too() -> None:
    made = gymnasium.make(SINGLE_ROBOT_ID, scenario=SMALL, teammates="idle", config=FAST)
    with pytest.raises(ValueError, match="unknown reset option 'randomise_starts'"):
        made.reset(seed=0, options={"randomise_starts": True})
    made.reset(seed=0, options={"randomize_starts": True})


def test_unknown_constructor_options_are_refused_by_name_in_one_line() -> None:
    import mrslam_env

    with pytest.raises(TypeError) as raised:
        parallel_env(scenario=SMALL, privilaged=True, max_cycle=3)
    message = str(raised.value)
    assert "\n" not in message
    assert "unknown env option 'privilaged', 'max_cycle';" in message
    for key in ("scenario", "config", "max_cycles", "privileged"):
        assert f"'{key}'" in message
    with pytest.raises(TypeError, match="unknown env option 'privilaged'"):
        mrslam_env.env(scenario=SMALL, privilaged=True)
    with pytest.raises(TypeError, match="privilaged"):  # Python's own line names it
        gymnasium.make(SINGLE_ROBOT_ID, scenario=SMALL, privilaged=True)


def test_the_known_options_are_those_the_card_documents() -> None:
    import mrslam_env.env as module
    from mrslam_env.env import RESET_OPTIONS

    assert module.__doc__ is not None
    episodes = " ".join(module.__doc__.split("Episodes")[1].split("Infos")[0].split())
    assert "Other option keys are ignored" not in episodes
    assert "Any other key raises ``ValueError``" in episodes
    for key in RESET_OPTIONS:
        assert f'"{key}"' in module.__doc__


def test_one_robot_has_empty_peer_and_comm_parts_and_passes_the_api_test() -> None:
    env = MultiRobotSlamEnv(scenario=SMALL, n_robots=1, seed=3, config=FAST)
    space = env.observation_space("robot_0")
    assert isinstance(space, gymnasium.spaces.Dict)
    assert space["peer"].shape == (0, 4)
    assert space["comm"].shape == (0,)
    assert env.action_space("robot_0").shape == (2,)
    observations, infos = env.reset(seed=3)
    assert list(observations) == ["robot_0"] == list(infos)
    assert space.contains(observations["robot_0"])
    observations, rewards, _, _, _ = env.step({"robot_0": np.array([0.5, 0.2], np.float32)})
    assert space.contains(observations["robot_0"])
    assert rewards["robot_0"] >= 0.0
    assert env.state().shape == env.state_space.shape
    parallel_api_test(MultiRobotSlamEnv(scenario=SMALL, n_robots=1, seed=0, config=FAST), 20)


def test_one_robot_flat_observation_fits_its_space() -> None:
    config = replace(FAST, flat_observation=True)
    env = MultiRobotSlamEnv(scenario=SMALL, n_robots=1, seed=1, config=config)
    observations, _ = env.reset(seed=1)
    assert env.observation_space("robot_0").contains(observations["robot_0"])
    alone = SingleRobotEnv(scenario=SMALL, n_robots=1, teammates="idle", config=FAST)
    observation, _ = alone.reset(seed=0)
    assert alone.observation_space.contains(observation)
