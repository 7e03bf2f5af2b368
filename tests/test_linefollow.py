"""Line following (thesis case study 2): image generator, the vision against the image's true
centreline, and a shortened run on the dynamic plant measured from its physical TCP."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from pyopenshowvar_apps.casestudies import linefollow_vision as vision
from pyopenshowvar_apps.casestudies.linefollow import (
    Table,
    camera_pose,
    detect_path,
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


def test_trace_finds_path_inside_region_and_prefers_centre() -> None:
    mask = _bar()
    # start and goal on the rim (row 10), far apart: the cheapest path dives to the centre
    path = vision.trace(mask, (10, 6), (10, 73), centre_weight=4.0)
    assert path[0] == (10, 6) and path[-1] == (10, 73)
    assert all(mask[p] for p in path)
    assert all(max(abs(a[0] - b[0]), abs(a[1] - b[1])) == 1 for a, b in itertools.pairwise(path))
    rows = np.array([r for r, _ in path[10:-10]])
    assert np.all(np.abs(rows - 19.5) <= 1.0)  # on the ridge (rows 19/20), not along row 10


def test_trace_without_centre_weight_takes_the_straight_rim() -> None:
    path = vision.trace(_bar(), (10, 6), (10, 73), centre_weight=0.0)
    assert {r for r, _ in path} == {10}


def test_trace_no_path_is_a_clear_error() -> None:
    mask = _bar()
    mask[:, 40] = False  # cut the bar in two
    with pytest.raises(vision.NoPathError, match="no traversable path"):
        vision.trace(mask, (20, 10), (20, 70))
    with pytest.raises(vision.NoPathError, match="not inside"):
        vision.trace(mask, (0, 0), (20, 70))
    with pytest.raises(vision.NoPathError, match="no line"):
        vision.segment(np.ones((20, 20)), threshold=0.5)


def test_tips_and_trimmed_centreline_of_a_round_capped_bar() -> None:
    """A stroke from x 20 to 60 drawn with a round marker of radius 8: its tips are 8 px
    beyond the stroke's ends; the centreline ends on them again."""
    yy, xx = np.mgrid[0:40, 0:80]
    dx = np.clip(xx, 20, 60) - xx
    mask = np.hypot(dx, yy - 20) <= 8.0
    a, b = sorted(vision.find_tips(mask), key=lambda p: p[1])
    assert abs(a[1] - 12) <= 1 and abs(b[1] - 68) <= 1
    dist = vision.distance_map(mask)
    line = vision.centreline(vision.trace(mask, a, b, dist=dist), dist)
    np.testing.assert_allclose(line[[0, -1], 0], [20, 60], atol=1.5)  # not 8 px off
    np.testing.assert_allclose(line[:, 1], 20, atol=1.0)


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
    det = detect_path(img.path)
    err = vision.polyline_distance(det.path_px, img.centreline)
    missed = vision.polyline_distance(img.centreline, det.path_px)
    assert err.max() < 1.2, err.max()  # px: no point of the detected line off the true one
    assert missed.max() < 1.5, missed.max()  # and it covers the whole line, ends included


async def test_line_following_on_the_dynamic_plant_against_the_true_line(tmp_path) -> None:
    """A short line, emulator 5x, dynamic plant: the robot's physical TCP (the plant's truth,
    sampled every cycle) stays within 2 mm of the true drawn centreline (thesis: < 5 mm)."""
    speed = 5.0
    img = generate_line_image(
        tmp_path / "line.png", width=200, height=150, n_points=3, seed=4, margin=30
    )
    store = parked_store(camera_pose(Table(200, 150), height_mm=30.0))
    config = EmulatorConfig(
        port=0, program="cart_path", speed=speed, latency="none", discovery=False, seed=2
    )
    async with Emulator(config, store=store) as emu, Client("127.0.0.1", emu.port) as client:
        plant = emu.robot.plant
        result = await run_line_following(
            client,
            img.path,
            duration_s=3.0,
            time_scale=speed,
            poll_s=0.005,
            ground_truth=img.centreline,
            truth=lambda: plant.truth.tcp[:3, 3],
            out_dir=tmp_path / "out",
            plots=False,  # the demo test draws them
        )
    m = result.metrics
    assert m["max_error_mm"] < 2.0, m
    assert m["rms_error_mm"] < 0.5, m
    assert m["detection_max_mm"] < 1.0 and m["tracking_max_mm"] < 1.0, m
    assert m["max_z_error_mm"] < 1.0, m
    assert m["samples"] > 50
    names = {p.name for p in result.files}
    assert {"linefollow_samples.csv", "linefollow_path.csv"} <= names
    assert all(p.stat().st_size > 0 for p in result.files)
    assert result.thesis == {"max_error_mm": "< 5"}  # the 10 s is set by the app, not compared


def test_table_mapping_centre_and_axes() -> None:
    t = Table(101, 51, 0.5, (500.0, 0.0, 300.0, -90.0))
    p = t.to_base(np.array([[50.0, 25.0], [60.0, 25.0], [50.0, 15.0]]))
    assert np.allclose(p[0], [500, 0, 300])
    assert np.allclose(p[1], [500, -5, 300])  # image x → base −Y
    assert np.allclose(p[2], [505, 0, 300])  # image up → base +X (away from the robot)
