"""Issue 36: map files that are not regular files, too large, or whose origin float64 cannot
hold to a cell are refused in one line before their data is read."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from mrslam_env.gridmap import FREE, GridMap
from mrslam_env.mapio import MapFileError, load_map, read_image, save_map


def write_yaml(path: Path, **changes: object) -> Path:
    document = {
        "image": "map.pgm",
        "resolution": 0.05,
        "origin": [-1.0, 2.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        **changes,
    }
    path.write_text(yaml.safe_dump(document))
    return path


def small_map(folder: Path, origin: tuple[float, float] = (0.0, 0.0)) -> Path:
    grid = GridMap(cells=np.full((20, 30), FREE, dtype=np.int8), resolution=0.05, origin=origin)
    return save_map(folder / "map.yaml", grid)


def test_a_fifo_as_the_yaml_is_refused_without_opening_it(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "fifo.yaml")  # opening it to read would block for ever
    with pytest.raises(MapFileError, match=r"fifo\.yaml: not a regular file \(a FIFO\)"):
        load_map(tmp_path / "fifo.yaml")


@pytest.mark.parametrize("link", [False, True])
def test_a_device_as_the_yaml_is_refused_without_reading_it(tmp_path: Path, link: bool) -> None:
    path = Path("/dev/zero")  # read to the end, it never ends
    if link:
        (tmp_path / "zero.yaml").symlink_to(path)
        path = tmp_path / "zero.yaml"
    with pytest.raises(MapFileError, match=r"not a regular file \(a character device"):
        load_map(path)


def test_a_yaml_over_1_mib_is_refused(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "map.yaml")
    with path.open("a") as handle:
        handle.write("# " + "x" * (1 << 20) + "\n")
    with pytest.raises(MapFileError, match=r"map\.yaml: map YAML of [\d,]+ bytes; the limit is"):
        load_map(path)


@pytest.mark.parametrize("image", ["/dev/zero", "fifo.pgm", "folder"])
def test_an_image_that_is_not_a_regular_file_is_refused(tmp_path: Path, image: str) -> None:
    if image == "fifo.pgm":
        os.mkfifo(tmp_path / image)
    if image == "folder":
        (tmp_path / image).mkdir()
    path = write_yaml(tmp_path / "map.yaml", image=image)
    with pytest.raises(MapFileError, match="not a regular file") as error:
        load_map(path)
    assert image in str(error.value)
    with pytest.raises(MapFileError, match="not a regular file"):
        read_image(image if image.startswith("/") else tmp_path / image)


def test_an_image_file_over_the_size_limit_is_refused_before_reading(tmp_path: Path) -> None:
    path = tmp_path / "map.pgm"
    with path.open("wb") as handle:  # a valid small header, then a sparse hole of 0.5 GB
        handle.write(b"P5\n10 10\n255\n" + bytes(100))
        handle.truncate(500_000_000)
    with pytest.raises(MapFileError, match=r"image file of [\d,]+ bytes; the limit is"):
        read_image(path)


def test_an_image_header_over_the_cell_limit_is_refused_before_its_data(tmp_path: Path) -> None:
    path = tmp_path / "map.pgm"
    path.write_bytes(b"P5\n20000 20000\n255\n" + bytes(10))
    with pytest.raises(MapFileError, match="the limit is 100,000,000"):
        read_image(path)


@pytest.mark.parametrize("origin", [1e15, -1e15, 1e10])
def test_an_origin_float64_cannot_hold_to_a_cell_is_refused(tmp_path: Path, origin: float) -> None:
    small_map(tmp_path)
    path = write_yaml(tmp_path / "far.yaml", origin=[origin, 5.0, 0.0])
    with pytest.raises(MapFileError, match=r"far\.yaml: .*float64 spacing .* 1e-05 of the"):
        load_map(path)


@pytest.mark.parametrize(
    "origin", [(-500.0, 800.0), (1.0e5, -2.0e5), (-1.0e7, 1.0e7), (3.0e8, 0.0)]
)
def test_real_origins_load(tmp_path: Path, origin: tuple[float, float]) -> None:
    grid = load_map(small_map(tmp_path, origin))
    assert grid.origin == origin and grid.shape == (20, 30)
