"""Camera imperfections against pictures whose right answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from wpbench.sim.camera_noise import CameraNoise, apply_camera_noise


def picture(size: int = 40):
    """A wall at 2 m (id 1) with a square door (id 2) 0.5 m in front of it in the middle."""
    ys, xs = np.mgrid[0:size, 0:size]
    x = (xs - size / 2) * 0.01
    y = (ys - size / 2) * 0.01
    depth = np.full((size, size), 2.0)
    seg = np.ones((size, size), dtype=np.int32)
    door = (np.abs(xs - size / 2) < size / 4) & (np.abs(ys - size / 2) < size / 4)
    depth[door], seg[door] = 1.5, 2
    position = np.stack([x, y, -depth, np.ones_like(depth)], axis=-1).astype(np.float32)
    return position, seg, door


def test_clean_camera_changes_nothing_and_draws_nothing():
    position, seg, _ = picture()
    rng = np.random.default_rng(0)
    out_p, out_s = apply_camera_noise(position, seg, CameraNoise(), rng)
    assert out_p is position and out_s is seg
    assert rng.random() == np.random.default_rng(0).random()


def test_depth_noise_moves_points_along_their_rays_and_grows_with_depth():
    position, seg, door = picture(200)
    out, _ = apply_camera_noise(position, seg, CameraNoise(depth_std=0.01), np.random.default_rng(1))
    before, after = position[..., :3].astype(np.float64), out[..., :3].astype(np.float64)
    cos = np.sum(before * after, -1) / np.linalg.norm(before, axis=-1) / np.linalg.norm(after, axis=-1)
    assert np.all(cos > 1 - 1e-6)                                  # same ray
    error = np.linalg.norm(after, axis=-1) - np.linalg.norm(before, axis=-1)
    dist = np.linalg.norm(before, axis=-1)
    ratio = error[~door].std() / error[door].std()
    expected = np.mean(dist[~door] ** 2) / np.mean(dist[door] ** 2)
    assert abs(ratio / expected - 1) < 0.1


def test_edge_holes_drop_exactly_the_pixels_at_the_door_rim():
    position, seg, door = picture()
    _, out = apply_camera_noise(position, seg, CameraNoise(edge_holes=True), np.random.default_rng(0))
    rim = np.zeros_like(door)
    for axis in (0, 1):
        for shift in (1, -1):
            rim |= door != np.roll(door, shift, axis=axis)
    rim[0, :] = rim[-1, :] = rim[:, 0] = rim[:, -1] = False   # np.roll wraps; the picture's border is no edge
    assert np.array_equal(out == 0, rim)


def test_random_holes_drop_about_the_asked_share():
    position, seg, _ = picture(200)
    _, out = apply_camera_noise(position, seg, CameraNoise(hole_fraction=0.2), np.random.default_rng(2))
    assert abs((out == 0).mean() - 0.2) < 0.01


def test_segmentation_errors_stay_within_the_boundary_band():
    position, seg, door = picture(80)
    _, out = apply_camera_noise(position, seg, CameraNoise(boundary_px=2), np.random.default_rng(3))
    changed = out != seg
    ys, xs = np.nonzero(changed)
    band = np.abs(np.maximum(np.abs(xs - 40), np.abs(ys - 40)) - 19.5) <= 2.5
    assert changed.any() and band.all()
    assert set(np.unique(out)) == {1, 2}
    near = np.zeros_like(door)
    ys, xs = np.mgrid[0:80, 0:80]
    near = np.abs(np.maximum(np.abs(xs - 40 + 0.5), np.abs(ys - 40 + 0.5)) - 20) <= 2
    assert 0.35 < changed[near].mean() < 0.65


@pytest.mark.parametrize("kwargs", [dict(depth_std=-1.0), dict(depth_std=float("nan")), dict(hole_fraction=1.0),
                                    dict(boundary_px=-1), dict(boundary_px=1.5)])
def test_bad_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        CameraNoise(**kwargs)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="position"):
        apply_camera_noise(np.zeros((4, 4)), np.zeros((4, 4)), CameraNoise(depth_std=0.1), np.random.default_rng(0))
