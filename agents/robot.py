"""The one description of the robot and its sensors the agents plan with: the env's.

:class:`~mrslam_env.config.EnvConfig` (its ``robot``, ``peer`` and ``dt``) is the truth.
An agent config that needs one of its figures (the footprint radius, the speeds at action
1, the acceleration limit, the control period, the peer sensor's range) holds a copy, and
the copy comes from the env in one way only:

* ``XConfig.for_env(env_config, **overrides)`` builds the config for that env; the
  overrides set tuning knobs, and overriding an env figure is a ``ValueError``;
* ``config.check_env(env_config)`` raises a ``ValueError`` naming the field, its value and
  the env's when a config contradicts the env; the agents' ``for_env`` constructors
  (``PathFollower.for_env``, ``ExplorerPolicy.for_env``, ``WanderPolicy.for_env``,
  ``TeamCoordinator.for_env``) build their config this way, or check the one given.

The configs' defaults for these fields are the default ``EnvConfig``'s figures, read from
it (:data:`DEFAULT_ENV`), never numbers of their own.
"""

from __future__ import annotations

from typing import Any, TypeVar

from mrslam_env.config import EnvConfig

__all__ = ["DEFAULT_ENV", "EnvFigures", "build_for_env", "check_against_env"]

DEFAULT_ENV = EnvConfig()
"""The default env, whose figures are the agent configs' defaults."""

EnvFigures = dict[str, tuple[str, object]]
"""Per config field, where the env holds its figure (``"robot.radius"``: the path in
``EnvConfig``) and the env's value."""

ConfigT = TypeVar("ConfigT")


def build_for_env(cls: type[ConfigT], figures: EnvFigures, overrides: dict[str, Any]) -> ConfigT:
    """``cls(**figures, **overrides)``; an override of an env figure is a ``ValueError``."""
    for name in sorted(set(overrides) & set(figures)):
        raise ValueError(
            f"{cls.__name__}.{name} comes from the env (EnvConfig.{figures[name][0]}): "
            f"set it in the EnvConfig, not as an override to {cls.__name__}.for_env"
        )
    return cls(**{name: value for name, (_, value) in figures.items()}, **overrides)


def check_against_env(config: object, figures: EnvFigures) -> None:
    """Raise a ``ValueError`` when a field of ``config`` differs from the env's figure."""
    cls_name = type(config).__name__
    for name, (source, value) in figures.items():
        mine = getattr(config, name)
        if mine != value:
            raise ValueError(
                f"{cls_name}.{name} is {mine!r} but the env's EnvConfig.{source} is "
                f"{value!r}: build the config with {cls_name}.for_env(env_config)"
            )
