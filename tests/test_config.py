"""Configuration dataclasses (mrslam_env.config): defaults are valid, bad values are rejected
with a message naming the class, the field and the value."""

from __future__ import annotations

import dataclasses
import math

import pytest

from mrslam_env.config import (
    CommConfig,
    EnvConfig,
    LidarConfig,
    OdometryConfig,
    PeerSensorConfig,
    RewardConfig,
    RobotConfig,
)

ALL = [
    RobotConfig,
    LidarConfig,
    OdometryConfig,
    PeerSensorConfig,
    CommConfig,
    RewardConfig,
    EnvConfig,
]

# (class, field) -> kind: "positive" (> 0), "non_negative" (>= 0), "probability" ([0, 1]).
FLOAT_FIELDS = {
    (RobotConfig, "radius"): "positive",
    (RobotConfig, "mass"): "positive",
    (RobotConfig, "max_speed"): "positive",
    (RobotConfig, "max_turn_rate"): "positive",
    (RobotConfig, "max_acceleration"): "positive",
    (RobotConfig, "max_angular_acceleration"): "positive",
    (LidarConfig, "max_range"): "positive",
    (LidarConfig, "range_noise_std"): "non_negative",
    (LidarConfig, "dropout_probability"): "probability",
    (OdometryConfig, "alpha1"): "non_negative",
    (OdometryConfig, "alpha2"): "non_negative",
    (OdometryConfig, "alpha3"): "non_negative",
    (OdometryConfig, "alpha4"): "non_negative",
    (PeerSensorConfig, "detect_range"): "positive",
    (PeerSensorConfig, "range_noise_std"): "non_negative",
    (PeerSensorConfig, "bearing_noise_std"): "non_negative",
    (PeerSensorConfig, "heading_noise_std"): "non_negative",
    (CommConfig, "comm_range"): "positive",
    (CommConfig, "packet_loss"): "probability",
    (RewardConfig, "area_weight"): "non_negative",
    (RewardConfig, "collision_penalty"): "non_negative",
    (RewardConfig, "coverage_resolution"): "positive",
    (RewardConfig, "team_novelty_weight"): "non_negative",
    (EnvConfig, "dt"): "positive",
    (EnvConfig, "flat_length_scale"): "positive",
}

BAD_VALUES = {
    "positive": [0.0, -1.0, math.nan, math.inf, -math.inf],
    "non_negative": [-1e-9, -1.0, math.nan, math.inf],
    "probability": [-0.01, 1.01, math.nan, math.inf],
}
GOOD_VALUES = {
    "positive": [1e-6, 3.0],
    "non_negative": [0.0, 2.5],
    "probability": [0.0, 0.5, 1.0],
}

CASES = [
    (cls, name, kind, value)
    for (cls, name), kind in FLOAT_FIELDS.items()
    for value in BAD_VALUES[kind]
]


def test_every_numeric_field_is_covered() -> None:
    numeric = {
        (cls, f.name)
        for cls in ALL
        for f in dataclasses.fields(cls)
        if isinstance(getattr(cls(), f.name), float)
    }
    assert numeric == set(FLOAT_FIELDS)


@pytest.mark.parametrize("cls", ALL)
def test_defaults_are_valid_and_frozen(cls) -> None:
    config = cls()
    first = dataclasses.fields(cls)[0].name
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(config, first, getattr(config, first))
    with pytest.raises(TypeError):
        cls(0.1)  # keyword-only


@pytest.mark.parametrize(
    ("cls", "name", "kind", "value"),
    CASES,
    ids=[f"{c.__name__}.{n}={v}" for c, n, _, v in CASES],
)
def test_bad_value_is_rejected_naming_the_field(cls, name: str, kind: str, value: float) -> None:
    with pytest.raises(ValueError) as error:
        cls(**{name: value})
    message = str(error.value)
    assert f"{cls.__name__}.{name}" in message
    assert repr(value) in message


@pytest.mark.parametrize(("cls", "name"), list(FLOAT_FIELDS))
def test_boundary_values_are_accepted(cls, name: str) -> None:
    for value in GOOD_VALUES[FLOAT_FIELDS[cls, name]]:
        assert getattr(cls(**{name: value}), name) == value


@pytest.mark.parametrize("value", [3, 0, -360, 4.0, 360.0, "360", None])
def test_lidar_n_beams_must_be_an_int_of_at_least_four(value) -> None:
    with pytest.raises(ValueError, match=r"LidarConfig\.n_beams"):
        LidarConfig(n_beams=value)


def test_lidar_n_beams_accepts_small_and_odd_counts() -> None:
    assert LidarConfig(n_beams=4).n_beams == 4
    assert LidarConfig(n_beams=361).n_beams == 361


@pytest.mark.parametrize("name", ["physics_substeps", "max_cycles"])
@pytest.mark.parametrize("value", [0, -1, 2.0, 1.5, "3", None])
def test_env_integer_fields(name: str, value) -> None:
    with pytest.raises(ValueError, match=rf"EnvConfig\.{name}"):
        EnvConfig(**{name: value})


def test_env_integer_fields_accept_one() -> None:
    config = EnvConfig(physics_substeps=1, max_cycles=1)
    assert (config.physics_substeps, config.max_cycles) == (1, 1)


@pytest.mark.parametrize(
    "starts",
    [
        ((0.0, 0.0),),
        ((0.0, 0.0, 0.0, 0.0),),
        ((0.0, math.nan, 0.0),),
        ((0.0, 0.0, 0.0), (1.0, 1.0, math.inf)),
    ],
)
def test_env_starts_must_be_finite_triples(starts) -> None:
    with pytest.raises(ValueError, match=r"EnvConfig\.starts\[\d\]"):
        EnvConfig(starts=starts)


def test_env_starts_error_names_the_index() -> None:
    with pytest.raises(ValueError, match=r"EnvConfig\.starts\[1\]"):
        EnvConfig(starts=((0.0, 0.0, 0.0), (1.0, math.nan, 0.0)))
    assert EnvConfig(starts=((1.0, 2.0, 3.0),)).starts == ((1.0, 2.0, 3.0),)


def test_nested_configs_validate_on_replace() -> None:
    config = EnvConfig()
    with pytest.raises(ValueError, match=r"LidarConfig\.max_range"):
        dataclasses.replace(config, lidar=dataclasses.replace(config.lidar, max_range=-1.0))
    changed = dataclasses.replace(config, lidar=dataclasses.replace(config.lidar, n_beams=180))
    assert changed.lidar.n_beams == 180
    assert config.lidar.n_beams == LidarConfig().n_beams
    # Default factories give independent but equal sub-configs.
    assert EnvConfig().robot == EnvConfig().robot
