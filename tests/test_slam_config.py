"""SLAM configuration (mrslam_env.slam.config): defaults are valid, bad values are refused
with an error that names the field and the value."""

from __future__ import annotations

import dataclasses
import math

import pytest

from mrslam_env.slam.config import SLAM_MODES, GridConfig, MatcherConfig, SlamConfig


def test_defaults_are_valid_and_frozen() -> None:
    config = SlamConfig()
    assert config.mode == "slam"
    assert config.grid.resolution == 0.05
    assert set(SLAM_MODES) == {"slam", "pose_graph", "odometry", "ground_truth"}
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.mode = "odometry"  # type: ignore[misc]
    with pytest.raises(TypeError):
        SlamConfig("odometry")  # type: ignore[misc]  # keyword-only


def test_every_field_is_documented() -> None:
    source = {
        cls: __import__("inspect").getsource(cls) for cls in (GridConfig, MatcherConfig, SlamConfig)
    }
    for cls, text in source.items():
        for field in dataclasses.fields(cls):
            declaration = text.split(f"    {field.name}:", 1)[1]
            # The line after the declaration is the field's docstring.
            assert declaration.split("\n", 2)[1].strip().startswith('"""'), (cls, field.name)


@pytest.mark.parametrize(
    ("cls", "field", "value"),
    [
        (GridConfig, "resolution", 0.0),
        (GridConfig, "resolution", math.nan),
        (GridConfig, "log_odds_hit", -0.1),
        (GridConfig, "log_odds_miss", 0.2),
        (GridConfig, "log_odds_miss_held", 0.0),
        (GridConfig, "log_odds_miss_held", -0.5),
        (GridConfig, "log_odds_miss_held", math.nan),
        (GridConfig, "log_odds_min", 0.0),
        (GridConfig, "log_odds_max", -1.0),
        (GridConfig, "occupied_threshold", 10.0),
        (GridConfig, "free_threshold", 0.5),
        (GridConfig, "free_threshold", -5.0),
        (GridConfig, "no_return_clear_distance", -1.0),
        (GridConfig, "growth_chunk", 0),
        (GridConfig, "growth_chunk", 63),
        (GridConfig, "growth_chunk", 64.0),
        (GridConfig, "fine_sigma", 0.0),
        (MatcherConfig, "coarse_angle_step", 0.0),
        (MatcherConfig, "fine_angle_step", 1.0),
        (MatcherConfig, "angle_window_base", -0.1),
        (MatcherConfig, "min_points", 0),
        (MatcherConfig, "min_score", 1.5),
        (MatcherConfig, "degenerate_ratio", -0.1),
        (MatcherConfig, "refine_iterations", 2.5),
        (MatcherConfig, "residual_std", math.inf),
        (MatcherConfig, "fine_search_cells", -1),
        (SlamConfig, "mode", "lidar_only"),
        (SlamConfig, "min_translation", -0.01),
        (SlamConfig, "integrate_rejected_after", 0),
        (SlamConfig, "grid", "fine"),
    ],
)
def test_bad_values_are_refused_naming_field_and_value(
    cls: type, field: str, value: object
) -> None:
    with pytest.raises(ValueError) as caught:
        cls(**{field: value})
    message = str(caught.value)
    assert f"{cls.__name__}.{field}" in message
    assert repr(value) in message or str(value) in message


def test_nested_configs_are_validated_by_their_own_class() -> None:
    with pytest.raises(ValueError, match=r"GridConfig\.resolution"):
        SlamConfig(grid=GridConfig(resolution=-1.0))
    config = SlamConfig(mode="ground_truth", grid=GridConfig(resolution=0.1))
    assert dataclasses.replace(config, mode="odometry").grid.resolution == 0.1
