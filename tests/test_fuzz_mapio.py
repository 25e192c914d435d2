"""Property-based corruption of ROS map files (hypothesis).

Every corrupted file pair either loads to exactly the grid an independent reference reader
makes of the same bytes, or fails with one :class:`MapFileError` line naming the file:
never a traceback, never a silently different grid.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.mapio import MapFileError, grey_to_cells, load_map, save_map

SETTINGS = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,  # seeded: the same examples on every run
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)

ROWS, COLS = 7, 9


def original(tmp: Path) -> tuple[Path, bytes, str]:
    """A small valid map pair written by save_map; returns (folder, PGM bytes, YAML text)."""
    rng = np.random.default_rng(0)
    grid = GridMap(
        cells=rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], dtype=np.int8), size=(ROWS, COLS)),
        resolution=0.05,
        origin=(-1.0, 2.0),
    )
    save_map(tmp / "m.yaml", grid)
    return tmp, (tmp / "m.pgm").read_bytes(), (tmp / "m.yaml").read_text()


_HEADER = re.compile(
    rb"P5(?:\s+(?:#[^\n\r]*[\n\r])*\s*)?(\d+)\s+(?:#[^\n\r]*[\n\r]\s*)*"
    rb"(\d+)\s+(?:#[^\n\r]*[\n\r]\s*)*(\d+)\s"
)


def reference_pgm(data: bytes) -> np.ndarray | None:
    """The grey image a strict P5 reader makes of ``data`` (rows top first), or None when the
    bytes are not a valid 8-bit P5 image of exactly width x height samples."""
    match = _HEADER.match(data)
    if match is None:
        return None
    width, height, maxval = (int(g) for g in match.groups())
    raster = data[match.end() :]
    if not (width > 0 and height > 0 and 0 < maxval <= 255) or len(raster) != width * height:
        return None
    samples = np.frombuffer(raster, dtype=np.uint8).astype(np.int64)
    if samples.max() > maxval:
        return None
    return (samples * 255 // maxval).astype(np.uint8).reshape(height, width)


def check_load(folder: Path) -> GridMap | None:
    """load_map, asserting that a failure is one MapFileError line naming a file."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a yaw in the origin only warns
            return load_map(folder / "m.yaml")
    except MapFileError as error:
        message = str(error)
        assert "\n" not in message
        assert message.startswith(str(folder)), message
        return None


pgm_edits = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 200), st.integers(0, 255)),
    st.tuples(st.just("truncate"), st.integers(0, 200), st.just(0)),
    st.tuples(st.just("insert"), st.integers(0, 200), st.integers(0, 255)),
    st.tuples(st.just("delete"), st.integers(0, 200), st.just(0)),
    st.tuples(st.just("width"), st.integers(-3, 3), st.just(0)),
    st.tuples(st.just("height"), st.integers(-3, 3), st.just(0)),
    st.tuples(st.just("crlf"), st.just(0), st.just(0)),
    st.tuples(st.just("maxval"), st.integers(0, 70000), st.just(0)),
)


def apply_pgm_edit(data: bytes, edit: tuple[str, int, int]) -> bytes:
    kind, where, value = edit
    where = min(where, len(data))
    if kind == "flip" and where < len(data):
        return data[:where] + bytes([value]) + data[where + 1 :]
    if kind == "truncate":
        return data[:where]
    if kind == "insert":
        return data[:where] + bytes([value]) + data[where:]
    if kind == "delete":
        return data[:where] + data[where + 1 :]
    if kind in ("width", "height"):
        index = 0 if kind == "width" else 1

        def bump(match: re.Match[bytes]) -> bytes:
            numbers = [int(g) for g in match.groups()]
            numbers[index] = max(numbers[index] + where, 0)
            return f"{numbers[0]} {numbers[1]}\n".encode()

        return re.sub(rb"(\d+) (\d+)\n", bump, data, count=1)
    if kind == "crlf" and b"\n255\n" in data:
        header_end = data.index(b"\n255\n") + 5
        return data[:header_end].replace(b"\n", b"\r\n") + data[header_end:]
    if kind == "maxval":
        return data.replace(b"\n255\n", f"\n{where}\n".encode(), 1)
    return data


@SETTINGS
@given(edits=st.lists(pgm_edits, min_size=1, max_size=3))
def test_corrupt_pgm_loads_exactly_or_fails_in_one_line(tmp_path: Path, edits) -> None:
    folder, pgm, _ = original(tmp_path)
    data = pgm
    for edit in edits:
        data = apply_pgm_edit(data, edit)
    (folder / "m.pgm").write_bytes(data)
    loaded = check_load(folder)
    expected = reference_pgm(data)
    if expected is None:
        assert loaded is None, f"accepted an invalid image: {data[:40]!r}"
        return
    assert loaded is not None, f"refused a valid image: {data[:40]!r}"
    cells = grey_to_cells(expected, negate=False, occupied_thresh=0.65, free_thresh=0.196)
    np.testing.assert_array_equal(loaded.cells, cells[::-1])


yaml_values = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.floats(-10, 10), max_size=4),
)
yaml_keys = st.sampled_from(
    ["image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"]
)


@SETTINGS
@given(
    changes=st.dictionaries(yaml_keys, yaml_values, min_size=1, max_size=3),
    dropped=st.lists(yaml_keys, max_size=2),
)
def test_corrupt_yaml_loads_what_it_says_or_fails_in_one_line(
    tmp_path: Path, changes, dropped
) -> None:
    folder, pgm, text = original(tmp_path)
    document = yaml.safe_load(text)
    document.update(changes)
    for key in dropped:
        document.pop(key, None)
    (folder / "m.yaml").write_text(yaml.safe_dump(document))
    loaded = check_load(folder)
    if loaded is None:
        return
    # It loaded: then the file must have said a valid map, and the grid is what it says.
    assert document["image"] == "m.pgm"
    resolution = float(document["resolution"])
    assert math.isfinite(resolution) and resolution > 0
    assert loaded.resolution == resolution
    assert loaded.origin == (float(document["origin"][0]), float(document["origin"][1]))
    grey = reference_pgm(pgm)
    assert grey is not None
    cells = grey_to_cells(
        grey,
        negate=bool(document["negate"]),
        occupied_thresh=float(document["occupied_thresh"]),
        free_thresh=float(document["free_thresh"]),
        mode=str(document.get("mode", "trinary")),
    )
    np.testing.assert_array_equal(loaded.cells, cells[::-1])


@SETTINGS
@given(garbage=st.binary(max_size=64))
def test_arbitrary_bytes_as_yaml_fail_in_one_line(tmp_path: Path, garbage: bytes) -> None:
    folder, _, _ = original(tmp_path)
    (folder / "m.yaml").write_bytes(garbage)
    assert check_load(folder) is None
