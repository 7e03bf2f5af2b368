"""Line following (thesis case study 2): image generator, A*, and a shortened run on the emulator."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pyopenshowvar_apps.casestudies import linefollow_vision as vision
from pyopenshowvar_apps.casestudies.linefollow import (
    Table,
    camera_pose,
    parked_store,
    run_line_following,
)
from pyopenshowvar_apps.casestudies.lineimage import generate_line_image, load_centreline

from kukavarproxy_emu import Emulator, EmulatorConfig
from pyopenshowvar import Client


def _bar(h: int = 40, w: int = 80, top: int = 10, bottom: int = 30) -> np.ndarray:
    mask = np.zeros((h, w), dtype=bool)
    mask[top:bottom, 5 : w - 5] = True
    return mask


def test_astar_finds_path_inside_region_and_prefers_centre() -> None:
    mask = _bar()
    # start and goal on the rim (row 10), far apart: the cheapest path dives to the centre
    path = vision.astar(mask, (10, 6), (10, 73), centre_weight=4.0)
    assert path[0] == (10, 6) and path[-1] == (10, 73)
    assert all(mask[p] for p in path)
    assert all(max(abs(a[0] - b[0]), abs(a[1] - b[1])) == 1 for a, b in itertools.pairwise(path))
    rows = np.array([r for r, _ in path[10:-10]])
    assert np.all(np.abs(rows - 19.5) <= 1.0)  # on the ridge (rows 19/20), not along row 10


def test_astar_without_centre_weight_takes_the_straight_rim() -> None:
    path = vision.astar(_bar(), (10, 6), (10, 73), centre_weight=0.0)
    assert {r for r, _ in path} == {10}


def test_astar_no_path_is_a_clear_error() -> None:
    mask = _bar()
    mask[:, 40] = False  # cut the bar in two
    with pytest.raises(vision.NoPathError, match="no traversable path"):
        vision.astar(mask, (20, 10), (20, 70))
    with pytest.raises(vision.NoPathError, match="not inside"):
        vision.astar(mask, (0, 0), (20, 70))


def test_generator_is_deterministic_by_seed(tmp_path) -> None:
    a = generate_line_image(tmp_path / "a.png", width=200, height=150, seed=5)
    b = generate_line_image(tmp_path / "b.png", width=200, height=150, seed=5)
    c = generate_line_image(width=200, height=150, seed=6)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.centreline, b.centreline)
    assert not np.array_equal(a.image, c.image)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    assert np.allclose(load_centreline(a.centreline_path), a.centreline, atol=1e-3)


def test_detection_matches_ground_truth(tmp_path) -> None:
    img = generate_line_image(tmp_path / "l.png", width=240, height=180, seed=2, thickness=10)
    gray = vision.load_gray(str(img.path))
    mask = vision.segment(gray)
    ends = vision.find_endpoints(mask)
    path = vision.smooth_path(vision.astar(mask, *ends), 9)
    err = vision.polyline_distance(path, img.centreline)
    assert err[10:-10].max() < 1.0  # px, away from the round end caps
    assert err.max() < 5.0
    # the ends are the ends of the line (either direction)
    gt_ends = img.centreline[[0, -1]]
    got = path[[0, -1]]
    assert (
        min(
            np.linalg.norm(got - gt_ends, axis=1).max(),
            np.linalg.norm(got - gt_ends[::-1], axis=1).max(),
        )
        < 8.0
    )


async def test_line_following_on_emulator_meets_target(tmp_path) -> None:
    """A short line, emulator 5x: max deviation < 1 mm (thesis < 5 mm), files written."""
    speed = 5.0
    img = generate_line_image(
        tmp_path / "line.png", width=200, height=150, n_points=3, seed=4, margin=30
    )
    store = parked_store(camera_pose(Table(200, 150), height_mm=30.0))
    config = EmulatorConfig(
        port=0, program="cart_path", speed=speed, latency="none", discovery=False
    )
    async with Emulator(config, store=store) as emu, Client("127.0.0.1", emu.port) as client:
        result = await run_line_following(
            client,
            img.path,
            duration_s=3.0,
            time_scale=speed,
            poll_s=0.005,
            ground_truth=img.centreline,
            out_dir=tmp_path / "out",
        )
    m = result.metrics
    assert m["max_error_mm"] < 1.0, m
    assert m["rms_error_mm"] < 0.5, m
    assert m["max_z_error_mm"] < 1.0, m
    assert m["samples"] > 20
    assert 1.5 < m["execution_time_s"] < 8.0, m  # 3 s requested; wall-clock based, loose
    assert m["detection_error_mm"] < 3.0
    names = {p.name for p in result.files}
    assert {"linefollow_samples.csv", "linefollow_path.csv", "linefollow_error.png"} <= names
    assert all(p.stat().st_size > 0 for p in result.files)
    assert result.thesis["max_error_mm"] == "< 5"


def test_table_mapping_centre_and_axes() -> None:
    t = Table(101, 51, 0.5, (500.0, 0.0, 300.0, -90.0))
    p = t.to_base(np.array([[50.0, 25.0], [60.0, 25.0], [50.0, 15.0]]))
    assert np.allclose(p[0], [500, 0, 300])
    assert np.allclose(p[1], [500, -5, 300])  # image x → base −Y
    assert np.allclose(p[2], [505, 0, 300])  # image up → base +X (away from the robot)
