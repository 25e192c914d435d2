"""IR-SIM reference for ``mrslam bench sim``: the same world and robots, stepped by IR-SIM.

:func:`build_irsim_env` turns a :class:`~mrslam_env.sim.world.WorldSpec` into an
equivalent headless IR-SIM environment:

* every wall quad becomes a static polygon obstacle (world coordinates, pose 0);
* ``n_robots`` differential-drive robots (``diff`` kinematics, circle of
  ``robot_radius``) start at the world's start poses (automatic starts as in our
  simulator when the world has fewer);
* each robot carries a 2-D lidar of ``n_beams`` beams over the full circle with beam
  ``i`` at ``-pi + i * 2 pi / n_beams`` from the heading, as our lidar, with range
  ``max_range`` and Gaussian range noise;
* ``collision_mode: contact``: robots are pushed out of walls and each other the way
  our pymunk solver does it, so they keep driving and scanning instead of freezing at
  the first contact (IR-SIM's default ``stop`` mode would halt them for good);
* a fixed step of ``step_time`` seconds, no figure, no window, no keyboard or mouse.

:func:`irsim_steps_per_second` times only ``env.step`` with velocity commands; every
``env.step`` casts all lidars (``EnvBase._objects_sensor_step``), and the run is checked
afterwards to have advanced the clock and changed every scan.

IR-SIM is an optional dependency (``pip install mrslam[bench]``); nothing of it is
imported until a function here is called.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import math
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from mrslam_env.sim.world import WorldSpec

__all__ = ["build_irsim_env", "irsim_available", "irsim_steps_per_second"]

# Our default RobotConfig / LidarConfig, mirrored (IR-SIM clips commands to these).
MAX_SPEED = 1.0  # m/s
MAX_TURN_RATE = 2.0  # rad/s
MAX_ACCELERATION = 2.0  # m/s^2
MAX_ANGULAR_ACCELERATION = 6.0  # rad/s^2
RANGE_NOISE_STD = 0.01  # m

_COMMAND_HOLD_STEPS = 10  # a new random command every second at 0.1 s steps


def _import_irsim() -> Any:
    """Import IR-SIM quietly and leave matplotlib on the Agg backend.

    On import IR-SIM tries the TkAgg and Qt5Agg backends first and prints every failure;
    the prints are swallowed and the backend is put back to Agg, so no window can open.
    """
    import matplotlib

    with contextlib.redirect_stdout(io.StringIO()):
        import irsim
    if matplotlib.get_backend().lower() != "agg":
        matplotlib.use("Agg")
    return irsim


def irsim_available() -> bool:
    """Whether IR-SIM (``ir-sim``, import name ``irsim``) can be imported."""
    try:
        _import_irsim()
    except Exception:
        return False
    return True


def _robot_starts(world: WorldSpec, n_robots: int, robot_radius: float) -> np.ndarray:
    if n_robots < 1:
        raise ValueError(f"n_robots must be >= 1, got {n_robots}")
    if len(world.starts) >= n_robots:
        return np.asarray(world.starts[:n_robots], dtype=np.float64)
    from mrslam_env.sim.simulator import choose_starts

    return choose_starts(world, n_robots, robot_radius, np.random.default_rng(0))


def _world_config(
    world: WorldSpec,
    *,
    n_robots: int,
    n_beams: int,
    max_range: float,
    step_time: float,
    robot_radius: float,
    range_noise_std: float,
) -> dict[str, Any]:
    """The IR-SIM world description (the content of its YAML file)."""
    if n_beams < 2:
        raise ValueError(f"n_beams must be >= 2, got {n_beams}")
    if not (max_range > 0 and step_time > 0 and robot_radius > 0):
        raise ValueError("max_range, step_time and robot_radius must be > 0")
    starts = _robot_starts(world, n_robots, robot_radius)
    xmin, ymin, xmax, ymax = world.bounds
    # IR-SIM spreads ``number`` beams evenly from -angle_range/2 to +angle_range/2, both
    # ends included: angle_range = 2 pi (n - 1) / n gives our spacing of 2 pi / n, and a
    # mounting yaw of -pi / n puts beam 0 at -pi from the heading, like ours.
    increment = 2.0 * math.pi / n_beams
    lidar = {
        "name": "lidar2d",
        "range_min": 0.0,
        "range_max": float(max_range),
        "angle_range": increment * (n_beams - 1),
        "number": int(n_beams),
        "offset": [0.0, 0.0, -increment / 2.0],
        "noise": range_noise_std > 0,
        "std": float(range_noise_std),
    }
    robots = {
        "number": int(n_robots),
        "distribution": {"name": "manual"},
        "kinematics": {"name": "diff"},
        "shape": {"name": "circle", "radius": float(robot_radius)},
        "state": [[float(x), float(y), float(theta)] for x, y, theta in starts],
        "vel_max": [MAX_SPEED, MAX_TURN_RATE],
        "vel_min": [-MAX_SPEED, -MAX_TURN_RATE],
        "acce": [MAX_ACCELERATION, MAX_ANGULAR_ACCELERATION],
        "sensors": [lidar],
    }
    # One static polygon per wall, vertices in world coordinates (obstacle pose 0).
    walls = [
        {
            "shape": {"name": "polygon", "vertices": np.asarray(quad).tolist()},
            "state": [0.0, 0.0, 0.0],
        }
        for quad in world.walls
    ]
    return {
        "world": {
            "width": float(xmax - xmin),
            "height": float(ymax - ymin),
            "offset": [float(xmin), float(ymin)],
            "step_time": float(step_time),
            "sample_time": float(step_time),
            "step_mode": "internal",
            "control_mode": "auto",
            "collision_mode": "contact",
        },
        "robot": [robots],
        "obstacle": walls,
    }


def build_irsim_env(
    world: WorldSpec,
    *,
    n_robots: int = 2,
    n_beams: int = 360,
    max_range: float = 8.0,
    step_time: float = 0.1,
    robot_radius: float = 0.2,
    range_noise_std: float = RANGE_NOISE_STD,
) -> Any:
    """A headless IR-SIM environment equivalent to our simulator on ``world``.

    Robots are objects ``0 .. n_robots - 1``; drive them with
    ``env.step([[v, omega], ...], action_id=list(range(n_robots)))`` and read their scans
    with ``env.get_lidar_scan(i)["ranges"]`` (beam ``i`` at ``-pi + i * 2 pi / n_beams``
    from the heading). Call ``env.end(0)`` when done.

    Raises
    ------
    ImportError
        If IR-SIM is not installed.
    """
    import yaml

    irsim = _import_irsim()
    config = _world_config(
        world,
        n_robots=n_robots,
        n_beams=n_beams,
        max_range=max_range,
        step_time=step_time,
        robot_radius=robot_radius,
        range_noise_std=range_noise_std,
    )
    with tempfile.TemporaryDirectory(prefix="mrslam_irsim_") as tmp:
        path = Path(tmp) / "mrslam_world.yaml"
        path.write_text(yaml.safe_dump(config, sort_keys=False))
        options: dict[str, Any] = {"display": False, "save_ani": False, "log_level": "ERROR"}
        if "headless" in inspect.signature(irsim.EnvBase).parameters:
            options.update(headless=True, seed=0)
        else:  # older IR-SIM, without ``headless``
            options.update(disable_all_plot=True)
        with contextlib.redirect_stdout(io.StringIO()):
            env = irsim.make(str(path), **options)
    return env


def _commands(n_steps: int, n_robots: int, seed: int) -> list[list[list[float]]]:
    """Random piecewise-constant ``(v, omega)`` per robot, held for one second.

    Always forward (``v >= 0.3 m/s``) and turning, so every robot keeps moving and
    scanning new views; contacts slide robots along walls rather than stop them.
    """
    rng = np.random.default_rng(seed)
    n_holds = -(-n_steps // _COMMAND_HOLD_STEPS)
    v = rng.uniform(0.3 * MAX_SPEED, MAX_SPEED, (n_holds, n_robots))
    omega = rng.uniform(-MAX_TURN_RATE, MAX_TURN_RATE, (n_holds, n_robots))
    return [
        [[float(v[k, i]), float(omega[k, i])] for i in range(n_robots)]
        for k in (s // _COMMAND_HOLD_STEPS for s in range(n_steps))
    ]


def _scans(env: Any, n_robots: int) -> np.ndarray:
    return np.stack([np.array(env.get_lidar_scan(i)["ranges"], copy=True) for i in range(n_robots)])


def irsim_steps_per_second(
    world: WorldSpec,
    *,
    n_steps: int = 200,
    n_beams: int = 360,
    max_range: float = 8.0,
    step_time: float = 0.1,
    robot_radius: float = 0.2,
    repeats: int = 3,
    n_robots: int = 2,
    range_noise_std: float = RANGE_NOISE_STD,
) -> float:
    """IR-SIM steps per second on ``world``: median over ``repeats`` fresh environments.

    Each repeat builds the environment (untimed), then times ``n_steps`` calls of
    ``env.step`` with velocity commands for every robot; each call moves the robots,
    resolves contacts and casts every lidar.

    Raises
    ------
    RuntimeError
        If a run did not advance the simulation or left a scan unchanged, i.e. IR-SIM
        did not do the work being timed.
    """
    if n_steps < 1 or repeats < 1:
        raise ValueError(f"n_steps and repeats must be >= 1, got {n_steps}, {repeats}")
    rates = []
    for repeat in range(repeats):
        env = build_irsim_env(
            world,
            n_robots=n_robots,
            n_beams=n_beams,
            max_range=max_range,
            step_time=step_time,
            robot_radius=robot_radius,
            range_noise_std=range_noise_std,
        )
        try:
            commands = _commands(n_steps, n_robots, seed=repeat)
            ids = list(range(n_robots))
            scans_before = _scans(env, n_robots)
            time_before = float(env.time)
            step = env.step
            start = time.perf_counter()
            for command in commands:
                step(command, action_id=ids)
            elapsed = time.perf_counter() - start
            advanced = round((float(env.time) - time_before) / step_time)
            if advanced != n_steps:
                raise RuntimeError(f"IR-SIM advanced {advanced} steps instead of {n_steps}")
            unchanged = np.all(_scans(env, n_robots) == scans_before, axis=1)
            if np.any(unchanged):
                raise RuntimeError(
                    f"IR-SIM lidar of robot(s) {np.flatnonzero(unchanged).tolist()} never changed"
                )
        finally:
            with contextlib.redirect_stdout(io.StringIO()):
                env.end(0)
        rates.append(n_steps / max(elapsed, 1e-12))
    return float(statistics.median(rates))
