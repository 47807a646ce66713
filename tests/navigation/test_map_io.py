from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
import yaml

from omnical.errors import ConfigError
from omnical.navigation.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from omnical.navigation.map_io import (
    SHIPPED_WORLDS,
    load_map,
    occupancy_from_image,
    read_pgm,
    resolve_world,
    save_map,
)

from .conftest import room, world_yaml


def test_a_world_is_a_file_or_a_shipped_name(tmp_path: Path) -> None:
    shipped = Path(str(files("omnical").joinpath("data", "worlds")))
    for name in SHIPPED_WORLDS:
        path = resolve_world(name)
        assert path == resolve_world(f"{name}.yaml") == shipped / f"{name}.yaml"
        assert load_map(path).resolution_m > 0
    mine = tmp_path / "lab-8x6.yaml"  # a file of that name wins over the shipped world
    mine.write_text("image: lab.pgm\n", encoding="utf-8")
    assert resolve_world(mine) == mine
    with pytest.raises(ConfigError, match=r"^nowhere: no such floor plan file.*lab-8x6"):
        resolve_world("nowhere")
    with pytest.raises(ConfigError, match="no such floor plan"):
        resolve_world(tmp_path / "lab-8x6")  # a folder's name is no shipped world


def test_finding_a_world_imports_no_planner() -> None:
    # `omnical ros2 twin --world NAME` finds the file before it starts: through
    # services.navigation (SLAM's gtsam, scipy.ndimage, numba's planners) that took 1 s of its
    # 1.7-2.2 s start-up; issue 25 asks for 2 s
    probe = (
        "import sys; from omnical.navigation.map_io import load_map, resolve_world; "
        "load_map(resolve_world('lab-8x6')); "
        "print(sorted(m for m in ('gtsam', 'scipy.ndimage', 'numba', "
        "'omnical.services.navigation') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


def test_shipped_worlds_load() -> None:
    lab = load_map(world_yaml("lab-8x6"))
    assert lab.shape == (300, 400)
    assert lab.size_m == pytest.approx((8.0, 6.0))
    assert lab.resolution_m == 0.02
    assert lab.origin == (0.0, 0.0, 0.0)
    # the bottom-left corner cell is a wall and the outer wall closes the room
    assert lab.occupied[0, 0] and lab.occupied[:, 0].all()
    wh = load_map(world_yaml("warehouse-20x20"))
    assert wh.shape == (1000, 1000)
    assert 0.1 < wh.occupied.mean() < 0.3


def test_round_trip_keeps_trinary_cells(tmp_path: Path) -> None:
    cells = np.full((5, 7), FREE, dtype=np.int8)
    cells[0, 0] = OCCUPIED
    cells[4, 6] = UNKNOWN
    grid = OccupancyGrid(cells, 0.05, (1.0, -2.0, 0.0))
    pgm = save_map(grid, tmp_path / "m.yaml")
    assert pgm.read_bytes().startswith(b"P5")
    back = load_map(tmp_path / "m.yaml")
    np.testing.assert_array_equal(back.cells, cells)
    assert back.origin == grid.origin and back.resolution_m == 0.05
    img = read_pgm(pgm)
    assert img[-1, 0] == 0 and img[0, 6] == 205  # row 0 of the image is the top


def test_negate_and_thresholds() -> None:
    img = np.array([[0, 100, 254]], dtype=np.uint8)
    np.testing.assert_array_equal(occupancy_from_image(img)[0], [OCCUPIED, UNKNOWN, FREE])
    np.testing.assert_array_equal(
        occupancy_from_image(img, negate=True)[0], [FREE, UNKNOWN, OCCUPIED]
    )


def test_ascii_pgm_and_relative_image(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.pgm").write_text("P2\n# c\n2 1\n15\n0 15\n")
    (tmp_path / "a.yaml").write_text(
        "image: sub/a.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    grid = load_map(tmp_path / "a.yaml")
    np.testing.assert_array_equal(grid.cells, [[OCCUPIED, FREE]])


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("resolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n", "image"),
        ("image: a.pgm\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n", "resolution"),
        (
            "image: a.pgm\nresolution: -1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "resolution",
        ),
        (
            "image: a.pgm\nresolution: 0.1\norigin: [0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "origin",
        ),
        (
            "image: a.pgm\nresolution: 0.1\norigin: [0,0,0]\nnegate: 2\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "negate",
        ),
        (
            "image: a.pgm\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.1\nfree_thresh: 0.2\n",
            "free_thresh",
        ),
        (
            "image: a.pgm\nresolution: 0.1\norigin: [0,0,0]\nmode: fancy\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "mode",
        ),
        (
            "image: b.pgm\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
            "image",
        ),
    ],
)
def test_bad_yaml_names_file_and_field(tmp_path: Path, text: str, field: str) -> None:
    (tmp_path / "a.pgm").write_bytes(b"P5\n1 1\n255\n\x00")
    path = tmp_path / "m.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"m\.yaml: {field}: "):
        load_map(path)


@pytest.mark.parametrize("body", [b"P6\n1 1\n255\n\x00\x00\x00", b"P5\n4 4\n255\n\x00", b"P5\n"])
def test_bad_image(tmp_path: Path, body: bytes) -> None:
    (tmp_path / "a.pgm").write_bytes(body)
    (tmp_path / "m.yaml").write_text(
        "image: a.pgm\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n"
    )
    with pytest.raises(ConfigError, match=r"a\.pgm: "):
        load_map(tmp_path / "m.yaml")


def test_an_image_that_is_no_image_is_named(tmp_path: Path) -> None:
    """``image: /etc/passwd`` said "cannot identify image file <_io.BytesIO object at 0x…>"."""
    text = tmp_path / "passwd"
    text.write_text("root:x:0:0:root:/root:/bin/bash\n")
    (tmp_path / "m.yaml").write_text(
        f"image: {text}\nresolution: 0.1\norigin: [0,0,0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n"
    )
    with pytest.raises(ConfigError) as err:
        load_map(tmp_path / "m.yaml")
    assert str(err.value) == f"{text}: not a PGM or PNG image (nor another format Pillow reads)"


def test_grid_transforms() -> None:
    grid = room()
    rc = np.array([[3, 4], [10, 70]])
    centres = grid.cell_to_world(rc)
    np.testing.assert_allclose(centres[0], [-1.0 + 4.5 * 0.05, -0.5 + 3.5 * 0.05])
    np.testing.assert_array_equal(grid.world_to_cell(centres), rc)
    rotated = OccupancyGrid(grid.cells, 0.05, (1.0, 2.0, 0.7))
    np.testing.assert_array_equal(rotated.world_to_cell(rotated.cell_to_world(rc)), rc)
    assert grid.value_at(np.array([[-5.0, 0.0]]))[0] == UNKNOWN


def test_grid_rejects_bad_values() -> None:
    with pytest.raises(ConfigError, match="cells must be"):
        OccupancyGrid(np.array([[5]], dtype=np.int8), 0.1)
    with pytest.raises(ConfigError, match="resolution"):
        OccupancyGrid(np.zeros((2, 2), dtype=np.int8), 0.0)


_GOOD = {
    "image": "a.pgm",
    "resolution": 0.05,
    "origin": [0.0, 0.0, 0.0],
    "occupied_thresh": 0.65,
    "free_thresh": 0.2,
}


@pytest.mark.parametrize(
    ("key", "value", "reason"),
    [
        ("resolution", 1e300, "must be 0.001 to 10 m per cell, got 1e+300"),
        ("resolution", 1e-300, "must be 0.001 to 10 m per cell, got 1e-300"),
        ("resolution", 0.0005, "must be 0.001 to 10 m per cell"),
        ("origin", [1e300, 0.0, 0.0], "x, y must lie within ±10000 m"),
        ("origin", [0.0, -2e4, 0.0], "x, y must lie within ±10000 m"),
        ("origin", [0.0, 0.0, 100.0], "yaw within ±2π rad"),
    ],
)
def test_map_values_out_of_any_map_are_refused(
    tmp_path: Path, key: str, value: object, reason: str
) -> None:
    (tmp_path / "a.pgm").write_bytes(b"P5\n2 2\n255\n\x00\xfe\xfe\xfe")
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump({**_GOOD, key: value}))
    with pytest.raises(ConfigError, match=rf"m\.yaml: {key}: .*{re.escape(reason)}"):
        load_map(path)
    for resolution, origin in ((0.001, [1e4, -1e4, 6.28]), (10.0, [0.0, 0.0, -6.28])):
        path.write_text(yaml.safe_dump({**_GOOD, "resolution": resolution, "origin": origin}))
        assert load_map(path).resolution_m == resolution  # the ends of the ranges load


@pytest.mark.parametrize("kind", ["character device", "FIFO", "directory"])
def test_a_map_image_that_is_not_a_regular_file_is_named_as_such(tmp_path: Path, kind: str) -> None:
    """/dev/zero, a FIFO or a directory was "does not exist"; a FIFO must not be opened."""
    image = {"character device": Path("/dev/zero"), "FIFO": tmp_path / "f", "directory": tmp_path}
    if kind == "FIFO":
        os.mkfifo(image[kind])
    path = tmp_path / "m.yaml"
    path.write_text(
        f"image: {image[kind]}\nresolution: 0.05\norigin: [0, 0, 0]\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.2\n"
    )
    reason = (
        "is a directory, not an image file"
        if kind == "directory"
        else (f"is not a regular file (a {kind})")
    )
    with pytest.raises(ConfigError) as err:
        load_map(path)
    assert str(err.value) == f"{path}: image: {image[kind]} {reason}"


def test_an_image_header_larger_than_any_map_is_refused(tmp_path: Path) -> None:
    (tmp_path / "a.pgm").write_bytes(b"P5\n100000 100000\n255\n\x00")
    with pytest.raises(ConfigError, match=r"a\.pgm: 100000x100000 pixels is too large a map"):
        read_pgm(tmp_path / "a.pgm")


def test_points_however_far_are_outside_without_a_numpy_warning() -> None:
    grid = room()
    rotated = OccupancyGrid(grid.cells, 0.001, (1e4, -1e4, 0.7))
    far = np.array([[1e308, 0.0], [-1.7e308, 1.7e308], [np.nan, 0.0], [np.inf, -np.inf]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for g in (grid, rotated):
            assert not g.in_bounds(g.world_to_cell(far)).any()
            assert (g.value_at(far) == UNKNOWN).all()
