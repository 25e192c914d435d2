"""Tests for mrslam_env.mapio: ROS map_server files (docs/design.md §2)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.mapio import (
    MapFileError,
    grey_to_cells,
    load_map,
    load_map_lattice,
    read_image,
    save_map,
)

FR, OC, UN = int(FREE), int(OCCUPIED), int(UNKNOWN)

YAML_KEYS = {
    "image": "map.pgm",
    "resolution": 0.05,
    "origin": [-1.0, 2.0, 0.0],
    "negate": 0,
    "occupied_thresh": 0.65,
    "free_thresh": 0.196,
}


def write_pgm(path: Path, image: np.ndarray, maxval: int = 255, comment: bool = True) -> None:
    """A binary PGM with image row 0 at the top, as map_server expects."""
    height, width = image.shape
    note = b"# written by a test\n" if comment else b""
    path.write_bytes(
        b"P5\n" + note + f"{width} {height}\n{maxval}\n".encode() + image.astype(np.uint8).tobytes()
    )


def write_yaml(path: Path, **overrides: object) -> Path:
    document = {**YAML_KEYS, **overrides}
    document = {key: value for key, value in document.items() if value is not None}
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


def random_grid(rng: np.random.Generator, shape: tuple[int, int]) -> GridMap:
    cells = rng.choice(np.array([FR, OC, UN], dtype=np.int8), size=shape)
    return GridMap(cells=cells, resolution=0.05, origin=(-12.345, 6.789))


# --------------------------------------------------------------------------------------
# Round trip and the written format


def test_round_trip_is_exact(tmp_path: Path) -> None:
    grid = random_grid(np.random.default_rng(1), (37, 53))
    yaml_path = save_map(tmp_path / "lab.yaml", grid)
    loaded = load_map(yaml_path)
    np.testing.assert_array_equal(loaded.cells, grid.cells)
    assert loaded.resolution == grid.resolution
    assert loaded.origin == grid.origin


@pytest.mark.parametrize("resolution", [0.05, 0.1, 1e-5, 0.025000000000000001, 1.0 / 3.0])
def test_round_trip_keeps_awkward_floats(tmp_path: Path, resolution: float) -> None:
    grid = GridMap(
        cells=np.array([[FR, OC], [UN, FR]], dtype=np.int8),
        resolution=resolution,
        origin=(1e-7, -123456.7890123),
    )
    loaded = load_map(save_map(tmp_path / "m.yaml", grid))
    assert loaded.resolution == resolution
    assert loaded.origin == grid.origin


def test_saved_files_follow_map_saver(tmp_path: Path) -> None:
    cells = np.array([[OC, FR, UN], [FR, FR, FR]], dtype=np.int8)  # row 0 is the bottom
    grid = GridMap(cells=cells, resolution=0.1, origin=(2.0, -3.0))
    yaml_path = save_map(tmp_path / "out.yaml", grid, image_name="images/out_map.pgm")
    document = yaml.safe_load(yaml_path.read_text())
    assert document == {
        "image": "images/out_map.pgm",
        "mode": "trinary",
        "resolution": 0.1,
        "origin": [2.0, -3.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    data = (tmp_path / "images" / "out_map.pgm").read_bytes()
    assert data.startswith(b"P5\n")
    pixels = np.frombuffer(data[-6:], dtype=np.uint8).reshape(2, 3)
    # Image top row = grid's highest row.
    np.testing.assert_array_equal(pixels, [[254, 254, 254], [0, 254, 205]])
    # Pillow agrees on the file's meaning.
    np.testing.assert_array_equal(
        np.asarray(Image.open(tmp_path / "images" / "out_map.pgm")), pixels
    )


def test_save_rejects_absolute_image_name(tmp_path: Path) -> None:
    grid = GridMap(cells=np.zeros((2, 2), dtype=np.int8), resolution=0.1)
    with pytest.raises(ValueError, match="relative"):
        save_map(tmp_path / "m.yaml", grid, image_name=str(tmp_path / "abs.pgm"))


# --------------------------------------------------------------------------------------
# Reading semantics


def test_y_flip_top_pixel_becomes_highest_row(tmp_path: Path) -> None:
    image = np.full((4, 5), 254, dtype=np.uint8)
    image[0, 3] = 0  # top of the picture
    write_pgm(tmp_path / "map.pgm", image)
    grid = load_map(write_yaml(tmp_path / "map.yaml"))
    assert grid.shape == (4, 5)
    assert np.argwhere(grid.occupied).tolist() == [[3, 3]]
    centre = grid.cell_to_world([3, 3])
    np.testing.assert_allclose(centre, [-1.0 + 3.5 * 0.05, 2.0 + 3.5 * 0.05], atol=1e-12)


GREY_LEVELS = np.array([[0, 49, 50, 89, 90, 128], [165, 166, 204, 205, 206, 255]], np.uint8)


def test_grey_levels_between_thresholds_are_unknown(tmp_path: Path) -> None:
    # p = (255 - v) / 255: occupied when p > 0.65 (v <= 89), free when p < 0.196 (v >= 206).
    write_pgm(tmp_path / "map.pgm", GREY_LEVELS)
    grid = load_map(write_yaml(tmp_path / "map.yaml"))
    expected_image = [[OC, OC, OC, OC, UN, UN], [UN, UN, UN, UN, FR, FR]]
    np.testing.assert_array_equal(grid.cells, np.array(expected_image)[::-1])


def test_negate_reads_white_as_occupied(tmp_path: Path) -> None:
    # With negate p = v / 255: occupied when v >= 166, free when v <= 49.
    write_pgm(tmp_path / "map.pgm", GREY_LEVELS)
    grid = load_map(write_yaml(tmp_path / "map.yaml", negate=1))
    expected_image = [[FR, FR, UN, UN, UN, UN], [UN, OC, OC, OC, OC, OC]]
    np.testing.assert_array_equal(grid.cells, np.array(expected_image)[::-1])


def test_negate_accepts_booleans(tmp_path: Path) -> None:
    write_pgm(tmp_path / "map.pgm", GREY_LEVELS)
    negated = load_map(write_yaml(tmp_path / "a.yaml", negate=True))
    plain = load_map(write_yaml(tmp_path / "b.yaml", negate=False))
    assert negated.cells[0, 1] == OC and plain.cells[0, 1] == UN  # v = 166
    assert negated.cells[1, 0] == FR and plain.cells[1, 0] == OC  # v = 0


def test_mode_scale_reduces_to_trinary(tmp_path: Path) -> None:
    write_pgm(tmp_path / "map.pgm", GREY_LEVELS)
    scale = load_map(write_yaml(tmp_path / "s.yaml", mode="scale"))
    trinary = load_map(write_yaml(tmp_path / "t.yaml", mode="trinary"))
    np.testing.assert_array_equal(scale.cells, trinary.cells)
    assert (scale.cells == UN).sum() == 6


def test_mode_raw_reads_percent(tmp_path: Path) -> None:
    image = np.array([[0, 19, 20, 64, 65, 100, 101, 255]], dtype=np.uint8)
    write_pgm(tmp_path / "map.pgm", image)
    grid = load_map(write_yaml(tmp_path / "map.yaml", mode="raw"))
    np.testing.assert_array_equal(grid.cells[0], [FR, FR, UN, UN, OC, OC, UN, UN])


def test_custom_thresholds(tmp_path: Path) -> None:
    image = np.array([[0, 100, 200, 255]], dtype=np.uint8)  # p = 1, .608, .216, 0
    write_pgm(tmp_path / "map.pgm", image)
    grid = load_map(write_yaml(tmp_path / "map.yaml", occupied_thresh=0.5, free_thresh=0.25))
    np.testing.assert_array_equal(grid.cells[0], [OC, OC, FR, FR])


def test_thresholds_are_strict(tmp_path: Path) -> None:
    # p exactly at a threshold is neither occupied nor free (map_server uses > and <).
    image = np.array([[50, 51, 52, 203, 204, 205]], dtype=np.uint8)  # p(51) = 0.8, p(204) = 0.2
    write_pgm(tmp_path / "map.pgm", image)
    grid = load_map(write_yaml(tmp_path / "map.yaml", occupied_thresh=0.8, free_thresh=0.2))
    np.testing.assert_array_equal(grid.cells[0], [OC, UN, UN, UN, UN, FR])


def test_png_grey_and_colour(tmp_path: Path) -> None:
    grey = np.array([[0, 254], [205, 254]], dtype=np.uint8)
    Image.fromarray(grey, mode="L").save(tmp_path / "grey.png")
    grid = load_map(write_yaml(tmp_path / "g.yaml", image="grey.png"))
    np.testing.assert_array_equal(grid.cells, [[UN, FR], [OC, FR]])

    # Integer mean of R, G, B; alpha ignored (a transparent black pixel is still occupied).
    rgba = np.array(
        [[[0, 0, 0, 0], [255, 255, 252, 255]], [[200, 210, 206, 128], [250, 0, 0, 255]]],
        dtype=np.uint8,
    )  # means 0, 254, 205, 83
    Image.fromarray(rgba, mode="RGBA").save(tmp_path / "colour.png")
    grid = load_map(write_yaml(tmp_path / "c.yaml", image="colour.png"))
    np.testing.assert_array_equal(grid.cells, [[UN, OC], [OC, FR]])
    np.testing.assert_array_equal(read_image(tmp_path / "colour.png"), [[0, 254], [205, 83]])


def test_png_palette_and_bilevel(tmp_path: Path) -> None:
    bits = np.array([[True, False, True]])
    Image.fromarray(bits).save(tmp_path / "bits.png")
    np.testing.assert_array_equal(read_image(tmp_path / "bits.png"), [[255, 0, 255]])
    palette = Image.fromarray(np.array([[0, 254]], dtype=np.uint8), mode="L").convert("P")
    palette.save(tmp_path / "palette.png")
    np.testing.assert_array_equal(read_image(tmp_path / "palette.png"), [[0, 254]])


def test_ascii_pgm_with_small_maxval(tmp_path: Path) -> None:
    # maxval 15 is stretched to 0..255 (SDL_image): 15 -> 255, 12 -> 204, 0 -> 0.
    (tmp_path / "map.pgm").write_bytes(b"P2\n# ascii\n3 2\n15\n15 12 0\n0 0 15\n")
    np.testing.assert_array_equal(read_image(tmp_path / "map.pgm"), [[255, 204, 0], [0, 0, 255]])
    grid = load_map(write_yaml(tmp_path / "map.yaml"))
    np.testing.assert_array_equal(grid.cells, [[OC, OC, FR], [FR, UN, OC]])


def test_image_path_relative_to_yaml_folder(tmp_path: Path) -> None:
    (tmp_path / "maps" / "img").mkdir(parents=True)
    write_pgm(tmp_path / "maps" / "img" / "a.pgm", np.zeros((2, 2), np.uint8))
    grid = load_map(write_yaml(tmp_path / "maps" / "a.yaml", image="img/a.pgm"))
    assert grid.occupied.all()


def test_a_quarter_turn_yaw_turns_the_grid_exactly(tmp_path: Path) -> None:
    # The origin is the pose of the image's bottom-left corner in the map frame: with
    # yaw pi/2 the image's bottom row runs up the map's y axis from (1, 2).
    cells = np.array([[OC, FR, FR], [UN, FR, OC]], dtype=np.int8)  # row 0 = lowest y
    grid = GridMap(cells=cells, resolution=0.5, origin=(1.0, 2.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a yaw is read, not warned about
        loaded = load_map(save_map(tmp_path / "turned.yaml", grid, yaw=np.pi / 2))
    # Row 0 is the lowest y, so a counter-clockwise turn is numpy's clockwise one.
    np.testing.assert_array_equal(loaded.cells, np.rot90(cells, k=-1))
    assert loaded.origin == pytest.approx((0.0, 2.0))
    assert loaded.resolution == 0.5
    # The occupied corner cell [0, 0] (centre 0.25 m along the image's bottom row and
    # 0.25 m up from it) is at (1 - 0.25, 2 + 0.25) in the map frame.
    assert loaded.cells[tuple(loaded.world_to_cell([0.75, 2.25]))] == OC


def test_any_yaw_places_every_cell_where_the_file_says(tmp_path: Path) -> None:
    grid = random_grid(np.random.default_rng(4), (30, 40))
    yaw = 0.3
    loaded = load_map(save_map(tmp_path / "turned.yaml", grid, yaw=yaw))
    # Nearest cell: each loaded cell holds the lattice cell under its centre, taken back
    # through the origin pose (x0, y0, yaw).
    x0, y0 = grid.origin
    rows, cols = np.nonzero(loaded.cells != UN)
    centres = loaded.cell_to_world(np.stack([rows, cols], axis=1)) - np.array([x0, y0])
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.stack(
        [c * centres[:, 0] + s * centres[:, 1], -s * centres[:, 0] + c * centres[:, 1]], 1
    )
    source = grid.world_to_cell(local + np.array([x0, y0]))
    np.testing.assert_array_equal(loaded.cells[rows, cols], grid.cells[source[:, 0], source[:, 1]])
    # Nothing is lost: every lattice cell is picked at least once but for a few on the
    # rim (nearest-cell resampling at the same resolution), and the counts of the three
    # classes agree within 3 %.
    assert len(rows) >= 0.97 * (grid.cells != UN).sum()
    for value in (FR, OC):
        assert (loaded.cells == value).sum() == pytest.approx((grid.cells == value).sum(), rel=0.03)


def test_a_map_written_with_a_yaw_round_trips(tmp_path: Path) -> None:
    grid = random_grid(np.random.default_rng(2), (21, 34))
    path = save_map(tmp_path / "yawed.yaml", grid, yaw=-0.7)
    assert yaml.safe_load(path.read_text())["origin"] == [-12.345, 6.789, -0.7]
    lattice, yaw = load_map_lattice(path)
    np.testing.assert_array_equal(lattice.cells, grid.cells)
    assert (lattice.origin, lattice.resolution, yaw) == (grid.origin, grid.resolution, -0.7)
    # The map read in its frame, written (yaw 0) and read again is the same grid.
    in_frame = load_map(path)
    again = load_map(save_map(tmp_path / "again.yaml", in_frame))
    np.testing.assert_array_equal(again.cells, in_frame.cells)
    assert again.origin == in_frame.origin
    with pytest.raises(ValueError, match="yaw must be finite"):
        save_map(tmp_path / "bad.yaml", grid, yaw=float("nan"))


def test_zero_yaw_is_read_unchanged(tmp_path: Path) -> None:
    write_pgm(tmp_path / "map.pgm", GREY_LEVELS)
    lattice, yaw = load_map_lattice(write_yaml(tmp_path / "zero.yaml", origin=[1.0, 2.0, 0.0]))
    loaded = load_map(tmp_path / "zero.yaml")
    assert yaw == 0.0 and loaded.origin == lattice.origin == (1.0, 2.0)
    np.testing.assert_array_equal(loaded.cells, lattice.cells)


def test_grey_to_cells_rejects_unknown_mode() -> None:
    with pytest.raises(ValueError, match="unsupported map mode"):
        grey_to_cells(
            np.zeros((1, 1), np.uint8),
            negate=False,
            occupied_thresh=0.6,
            free_thresh=0.2,
            mode="fancy",
        )


# --------------------------------------------------------------------------------------
# Malformed input: one-line MapFileError naming the file and the problem


def _good_image(tmp_path: Path) -> None:
    write_pgm(tmp_path / "map.pgm", np.full((3, 4), 254, dtype=np.uint8))


MALFORMED_YAML = [
    ("missing key", {"resolution": None}, r"missing required key\(s\): resolution"),
    ("missing two", {"negate": None, "free_thresh": None}, "negate, free_thresh"),
    ("zero resolution", {"resolution": 0.0}, "resolution must be > 0"),
    ("negative resolution", {"resolution": -0.05}, "resolution must be > 0"),
    ("nan resolution", {"resolution": float("nan")}, "resolution must be finite"),
    ("text resolution", {"resolution": "fine"}, "resolution must be a number"),
    ("origin two numbers", {"origin": [1.0, 2.0]}, r"origin must be 3 numbers"),
    ("origin scalar", {"origin": 3.0}, r"origin must be 3 numbers"),
    ("origin text", {"origin": [1.0, "a", 0.0]}, "origin must be a number"),
    ("bad mode", {"mode": "colour"}, "unsupported mode 'colour'"),
    ("occupied above 1", {"occupied_thresh": 1.5}, r"occupied_thresh must lie in \[0, 1\]"),
    ("free below 0", {"free_thresh": -0.1}, r"free_thresh must lie in \[0, 1\]"),
    ("free above occupied", {"free_thresh": 0.7}, "must be below occupied_thresh"),
    ("free equals occupied", {"free_thresh": 0.65}, "must be below occupied_thresh"),
    ("negate 2", {"negate": 2}, "negate must be 0 or 1"),
    ("image not text", {"image": 5}, "image must be a file name"),
    ("missing image", {"image": "nowhere.pgm"}, "image file not found"),
]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [case[1:] for case in MALFORMED_YAML],
    ids=[case[0] for case in MALFORMED_YAML],
)
def test_malformed_yaml_values(tmp_path: Path, overrides: dict, message: str) -> None:
    _good_image(tmp_path)
    yaml_path = write_yaml(tmp_path / "map.yaml", **overrides)
    with pytest.raises(MapFileError, match=message) as raised:
        load_map(yaml_path)
    text = str(raised.value)
    assert text.startswith(str(yaml_path) + ": ")
    assert "\n" not in text


def test_missing_yaml(tmp_path: Path) -> None:
    with pytest.raises(MapFileError, match="map YAML file not found") as raised:
        load_map(tmp_path / "absent.yaml")
    assert "absent.yaml" in str(raised.value)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("image: map.pgm\nresolution: [0.05\n", r"invalid YAML syntax at line \d+, column \d+"),
        ("image: a: b: c\n", "invalid YAML syntax"),
        ("- just\n- a list\n", "must be a mapping of keys, got list"),
        ("", "must be a mapping of keys, got NoneType"),
    ],
)
def test_bad_yaml_syntax(tmp_path: Path, text: str, message: str) -> None:
    yaml_path = tmp_path / "map.yaml"
    yaml_path.write_text(text)
    with pytest.raises(MapFileError, match=message) as raised:
        load_map(yaml_path)
    assert "\n" not in str(raised.value)
    assert str(raised.value).startswith(str(yaml_path))


MALFORMED_IMAGES = [
    ("not an image", b"hello, this is text\n", "unreadable image"),
    ("empty file", b"", r"empty image file \(0 bytes\)"),
    (
        "truncated P5",
        b"P5\n4 3\n255\n" + bytes(5),
        r"data is 5 bytes but the header says 4 x 3 = 12",
    ),
    (
        "width one short",
        b"P5\n3 3\n255\n" + bytes(12),
        r"is 12 bytes but .* 3 x 3 = 9",
    ),
    (
        "CRLF header",
        b"P5\r\n4 3\r\n255\r\n" + bytes(12),
        r"= 12 \(header lines end in CRLF\)",
    ),
    (
        "truncated P2",
        b"P2\n2 2\n255\n1 2 3\n",
        r"has 3 values but the header says 2 x 2 = 4",
    ),
    (
        "extra P2 values",
        b"P2\n2 1\n255\n1 2 3\n",
        r"has 3 values but .* 2 x 1 = 2",
    ),
    ("16-bit PGM", b"P5\n2 1\n65535\n" + bytes(4), "16-bit images are not supported"),
    ("zero width", b"P5\n0 3\n255\n", r"empty image \(0 x 3 pixels\)"),
    ("header text", b"P5\nwide 3\n255\n", "corrupt PGM header: width"),
    ("header cut", b"P5\n4 3\n", "corrupt PGM header: missing maxval"),
    ("value above maxval", b"P2\n2 1\n15\n3 16\n", "pixel value above maxval 15"),
    ("corrupt png", b"\x89PNG\r\n\x1a\n" + bytes(30), "(corrupt|unreadable) image"),
]


@pytest.mark.parametrize(
    ("data", "message"),
    [case[1:] for case in MALFORMED_IMAGES],
    ids=[case[0] for case in MALFORMED_IMAGES],
)
def test_malformed_images(tmp_path: Path, data: bytes, message: str) -> None:
    (tmp_path / "map.pgm").write_bytes(data)
    yaml_path = write_yaml(tmp_path / "map.yaml")
    with pytest.raises(MapFileError, match=message) as raised:
        load_map(yaml_path)
    assert str(raised.value).startswith(str(tmp_path / "map.pgm") + ": ")
    assert "\n" not in str(raised.value)


def test_16_bit_png_is_rejected(tmp_path: Path) -> None:
    Image.fromarray(np.full((3, 3), 40000, dtype=np.uint16)).save(tmp_path / "deep.png")
    yaml_path = write_yaml(tmp_path / "map.yaml", image="deep.png")
    with pytest.raises(MapFileError, match="16-bit"):
        load_map(yaml_path)


def test_library_errors_are_chained(tmp_path: Path) -> None:
    (tmp_path / "map.yaml").write_text("image: [unclosed\n")
    with pytest.raises(MapFileError) as raised:
        load_map(tmp_path / "map.yaml")
    assert isinstance(raised.value.__cause__, yaml.YAMLError)
    assert isinstance(raised.value, ValueError)
