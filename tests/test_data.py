"""Training data: generation from the tasks (tiny, mesh observations), shards, manifest,
resume, dataset tensors, the yaw augmentation and the symmetric-target choice."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.data.augment import random_scale, random_slide_stretch, random_yaw
from wpbench.data.config import ARTICULATED, FREE, GenerationConfig
from wpbench.data.dataset import CrossPoseDataset
from wpbench.data.generate import generate, symmetric_min_rotation
from wpbench.data.manifest import read_manifest
from wpbench.data.shards import read_shard, shard_path
from wpbench.data.synthetic import write_synthetic_split


def _tiny_config(**kw) -> GenerationConfig:
    base = dict(split="train", obs="mesh", seed=3, samples_per_kind=2, shard_size=2, scene_reuse=2,
                num_action_points=32, num_anchor_points=64)
    base.update(kw)
    return GenerationConfig(**base)


@pytest.mark.slow
def test_generation_writes_manifest_and_shards_and_resumes_without_redoing_work(tmp_path):
    config = _tiny_config()
    report = generate(tmp_path, config, progress=False)
    assert report.written_shards == 2 and report.new_samples == 4
    manifest = read_manifest(tmp_path / "train")
    assert manifest["counts"] == {ARTICULATED: 2, FREE: 2}
    assert sum(manifest["counts_by_category"][ARTICULATED].values()) == 2
    art = read_shard(shard_path(tmp_path / "train", ARTICULATED, 0))
    free = read_shard(shard_path(tmp_path / "train", FREE, 0))
    assert art["action_points"].shape == (2, 32, 3) and art["anchor_points"].shape == (2, 64, 3)
    assert set(art["kind"]) == {0} and set(free["kind"]) == {1}
    assert np.all(free["free_object"] == "block") and np.all(np.isnan(free["start_fraction"]))
    assert np.all((art["start_fraction"] >= -1e-6) & (art["start_fraction"] <= 0.9 + 1e-6))
    for T in np.concatenate([art["gt_transform"], free["gt_transform"]]):
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6)
        np.testing.assert_allclose(T[3], [0, 0, 0, 1])

    # Second run: everything is on disk, nothing is redone.
    mtime = shard_path(tmp_path / "train", FREE, 0).stat().st_mtime_ns
    again = generate(tmp_path, config, progress=False)
    assert again.written_shards == 0 and again.new_samples == 0 and again.skipped_shards == 2
    assert shard_path(tmp_path / "train", FREE, 0).stat().st_mtime_ns == mtime

    # A lost shard is rewritten identically (samples depend on the seed only).
    shard_path(tmp_path / "train", ARTICULATED, 0).unlink()
    redo = generate(tmp_path, _tiny_config(kinds=(ARTICULATED,)), progress=False)
    assert redo.written_shards == 1
    rewritten = read_shard(shard_path(tmp_path / "train", ARTICULATED, 0))
    np.testing.assert_array_equal(rewritten["seed"], art["seed"])
    np.testing.assert_allclose(rewritten["gt_transform"], art["gt_transform"], atol=1e-9)
    np.testing.assert_allclose(rewritten["action_points"], art["action_points"], atol=1e-6)
    assert read_manifest(tmp_path / "train")["counts"] == {ARTICULATED: 2, FREE: 2}


def test_config_refuses_shards_that_split_a_scene():
    with pytest.raises(ValueError, match="multiple of scene_reuse"):
        _tiny_config(shard_size=3, scene_reuse=2)


def test_dataset_yields_consistent_tensors(tmp_path):
    write_synthetic_split(tmp_path, "train", per_kind=3, num_action_points=16, num_anchor_points=24)
    both = CrossPoseDataset(tmp_path / "train")
    assert len(both) == 6 and both.count(ARTICULATED) == 3 and both.count(FREE) == 3
    item = both[4]
    assert item["action"].shape == (16, 3) and item["anchor"].shape == (24, 3)
    assert item["action"].dtype == torch.float32 and item["gt_transform"].shape == (4, 4)
    assert int(item["kind"]) == 1 and int(item["index"]) == 4
    R = item["gt_transform"][:3, :3]
    torch.testing.assert_close(R @ R.T, torch.eye(3), atol=1e-5, rtol=0)
    only_free = CrossPoseDataset(tmp_path / "train", kinds=(FREE,))
    assert len(only_free) == 3 and bool((only_free.kind == 1).all())


def test_dataset_names_the_command_when_data_is_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="wpbench data generate"):
        CrossPoseDataset(tmp_path / "train")


@settings(max_examples=25)
@given(seed=st.integers(0, 2**31 - 1), mirror=st.booleans())
def test_yaw_augmentation_keeps_the_ground_truth_consistent(seed, mirror):
    g = torch.Generator().manual_seed(seed)
    B, N = 3, 20
    yaw = (torch.rand(B, generator=g, dtype=torch.float64) * 2 - 1) * math.pi
    T = torch.eye(4, dtype=torch.float64).repeat(B, 1, 1)
    axis = torch.nn.functional.normalize(torch.randn(B, 3, generator=g, dtype=torch.float64), dim=-1)
    K = torch.zeros(B, 3, 3, dtype=torch.float64)
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K = K - K.transpose(1, 2)
    T[:, :3, :3] = torch.linalg.matrix_exp(K * yaw[:, None, None])
    T[:, :3, 3] = torch.randn(B, 3, generator=g, dtype=torch.float64)
    p = torch.randn(B, N, 3, generator=g, dtype=torch.float64)
    goal = p @ T[:, :3, :3].transpose(1, 2) + T[:, :3, 3:].transpose(1, 2)
    # The goal rides along as the "anchor" so we can check T' p' = goal' after augmentation.
    out = random_yaw({"action": p, "anchor": goal, "gt_transform": T}, g, mirror=mirror)
    T2 = out["gt_transform"]
    moved = out["action"] @ T2[:, :3, :3].transpose(1, 2) + T2[:, :3, 3:].transpose(1, 2)
    torch.testing.assert_close(moved, out["anchor"], atol=1e-9, rtol=0)
    assert not torch.allclose(out["action"], p)  # the scene did turn
    torch.testing.assert_close(out["action"][..., 2], p[..., 2])  # about z only
    # Still a rigid motion (a mirror must not leak into T), rotating as much as before.
    R2 = T2[:, :3, :3]
    torch.testing.assert_close(R2 @ R2.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(B, 3, 3), atol=1e-9, rtol=0)
    torch.testing.assert_close(torch.linalg.det(R2), torch.ones(B, dtype=torch.float64), atol=1e-9, rtol=0)
    trace = lambda R: R.diagonal(dim1=-2, dim2=-1).sum(-1)  # noqa: E731
    torch.testing.assert_close(trace(R2), trace(T[:, :3, :3]), atol=1e-9, rtol=0)


@given(seed=st.integers(0, 2**31 - 1), spread=st.floats(0.01, 0.5))
def test_scale_augmentation_keeps_the_ground_truth_consistent_and_rotations_unchanged(seed, spread):
    g = torch.Generator().manual_seed(seed)
    B, N = 4, 12
    T = torch.eye(4, dtype=torch.float64).repeat(B, 1, 1)
    T[:, :3, :3] = torch.linalg.qr(torch.randn(B, 3, 3, generator=g, dtype=torch.float64)).Q
    T[:, :3, :3] *= torch.sign(torch.linalg.det(T[:, :3, :3]))[:, None, None]  # proper rotations
    T[:, :3, 3] = torch.randn(B, 3, generator=g, dtype=torch.float64)
    p = torch.randn(B, N, 3, generator=g, dtype=torch.float64)
    goal = p @ T[:, :3, :3].transpose(1, 2) + T[:, :3, 3:].transpose(1, 2)
    batch = {"action": p, "anchor": goal, "gt_transform": T, "gt_equivalents": torch.stack([T, T], dim=1)}
    out = random_scale(batch, spread, g)
    factor = out["action"].norm(dim=-1) / p.norm(dim=-1)  # (B, N): one factor per scene
    assert bool(((factor - factor[:, :1]).abs() < 1e-9).all())
    assert bool(((factor - 1).abs() <= spread + 1e-9).all())
    T2 = out["gt_transform"]
    moved = out["action"] @ T2[:, :3, :3].transpose(1, 2) + T2[:, :3, 3:].transpose(1, 2)
    torch.testing.assert_close(moved, out["anchor"], atol=1e-9, rtol=0)
    torch.testing.assert_close(T2[:, :3, :3], T[:, :3, :3])
    torch.testing.assert_close(out["gt_equivalents"][:, 1], T2)
    torch.testing.assert_close(batch["action"], p)  # the input batch is left alone


@pytest.mark.parametrize("augmentation", [random_scale, random_slide_stretch])
def test_scale_and_stretch_reject_a_spread_outside_0_1(augmentation):
    batch = {"action": torch.zeros(1, 2, 3), "anchor": torch.zeros(1, 2, 3), "gt_transform": torch.eye(4)[None],
             "kind": torch.zeros(1, dtype=torch.int64)}
    for spread in (-0.1, 1.0):
        with pytest.raises(ValueError, match="spread"):
            augmentation(batch, spread)


@settings(max_examples=30)
@given(seed=st.integers(0, 2**31 - 1), spread=st.floats(0.05, 0.5))
def test_slide_stretch_lengthens_drawer_scenes_along_the_slide_only(seed, spread):
    g = torch.Generator().manual_seed(seed)
    N = 16
    # Three scenes: a drawer (pure horizontal translation), a door (turn about z), a free block
    # that happens to move by a pure translation (kind 1: must be left alone too).
    heading = float(torch.rand(1, generator=g)) * 2 * math.pi
    slide = torch.tensor([math.cos(heading), math.sin(heading), 0.0], dtype=torch.float64)
    T = torch.eye(4, dtype=torch.float64).repeat(3, 1, 1)
    T[0, :3, 3] = (0.05 + 0.4 * float(torch.rand(1, generator=g))) * slide
    T[1, :2, :2] = torch.tensor([[0.0, -1.0], [1.0, 0.0]], dtype=torch.float64)
    T[1, :3, 3] = torch.tensor([0.3, -0.2, 0.0], dtype=torch.float64)
    T[2, :3, 3] = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
    p = torch.randn(3, N, 3, generator=g, dtype=torch.float64)
    goal = p @ T[:, :3, :3].transpose(1, 2) + T[:, :3, 3:].transpose(1, 2)
    batch = {"action": p, "anchor": goal, "gt_transform": T, "gt_equivalents": T[:, None].clone(),
             "kind": torch.tensor([0, 0, 1])}
    out = random_slide_stretch(batch, spread, g)
    T2 = out["gt_transform"]
    moved = out["action"] @ T2[:, :3, :3].transpose(1, 2) + T2[:, :3, 3:].transpose(1, 2)
    torch.testing.assert_close(moved, out["anchor"], atol=1e-9, rtol=0)  # the goal is still exact
    torch.testing.assert_close(out["gt_equivalents"][:, 0], T2)
    for key in ("action", "anchor", "gt_transform"):  # the door and the block are untouched
        torch.testing.assert_close(out[key][1:], batch[key][1:])
    # The drawer scene: lengths along the slide change by one factor in range, across it by none.
    factor = float(T2[0, :3, 3].norm() / T[0, :3, 3].norm())
    assert abs(factor - 1) <= spread + 1e-9
    along = lambda x: x @ slide  # noqa: E731
    across = lambda x: x - along(x)[..., None] * slide  # noqa: E731
    before, after = p[0] - p[0, :1], out["action"][0] - out["action"][0, :1]
    torch.testing.assert_close(along(after), factor * along(before), atol=1e-9, rtol=0)
    torch.testing.assert_close(across(after), across(before), atol=1e-9, rtol=0)
    torch.testing.assert_close(T2[0, :3, :3], torch.eye(3, dtype=torch.float64))


def test_mirror_augmentation_reflects_about_half_the_scenes():
    g = torch.Generator().manual_seed(0)
    B = 400
    p = torch.randn(B, 6, 3, dtype=torch.float64, generator=g)
    batch = {"action": p, "anchor": p.clone(), "gt_transform": torch.eye(4, dtype=torch.float64).repeat(B, 1, 1)}
    def orientation(x):  # sign of the triple product of three points: a reflection flips it
        return torch.sign(torch.linalg.det(x[:, :3] - x[:, 3:4]))
    plain = random_yaw(batch, torch.Generator().manual_seed(1), mirror=False)
    mirrored = random_yaw(batch, torch.Generator().manual_seed(1), mirror=True)
    assert bool((orientation(plain["action"]) == orientation(p)).all())  # a yaw never reflects
    flipped = (orientation(mirrored["action"]) != orientation(p)).double().mean()
    assert 0.4 < float(flipped) < 0.6


def test_symmetric_target_is_an_equivalent_pose_with_the_least_rotation():
    rng = np.random.default_rng(0)
    from scipy.spatial.transform import Rotation

    cube = np.array([m for m in Rotation.create_group("O").as_matrix()])
    for _ in range(10):
        O = np.eye(4)
        O[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        O[:3, 3] = rng.normal(size=3)
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        T[:3, 3] = rng.normal(size=3)
        best = symmetric_min_rotation(T, O, cube)
        angle = lambda M: np.arccos(np.clip((np.trace(M[:3, :3]) - 1) / 2, -1, 1))  # noqa: E731
        assert angle(best) <= angle(T) + 1e-9
        assert angle(best) <= np.radians(62.8 + 0.1)  # the octahedral group's covering radius
        # Equivalent: the object moved by `best` lands on the goal pose up to a symmetry.
        S = np.linalg.inv(T @ O) @ best @ O
        assert np.any([np.allclose(S[:3, :3], c, atol=1e-9) for c in cube])
        np.testing.assert_allclose(S[:3, 3], 0, atol=1e-9)


def test_extra_train_instances_change_the_fingerprint_only_when_used():
    from wpbench.data.config import GenerationConfig

    plain = GenerationConfig(split="train")
    assert GenerationConfig(split="train", extra_train_instances=0).sample_fingerprint() == plain.sample_fingerprint()
    assert GenerationConfig(split="train", extra_train_instances=48).sample_fingerprint() != plain.sample_fingerprint()
    with pytest.raises(ValueError, match="extra_train_instances"):
        GenerationConfig(split="train", extra_train_instances=-1)


@pytest.mark.slow
def test_two_workers_write_the_same_shards_as_one(tmp_path):
    config = _tiny_config(samples_per_kind=4)   # two shards of each kind
    serial = generate(tmp_path / "serial", config, progress=False)
    parallel = generate(tmp_path / "parallel", config, progress=False, workers=2)
    assert serial.written_shards == parallel.written_shards == 4
    for kind in (ARTICULATED, FREE):
        for index in range(2):
            one = read_shard(shard_path(tmp_path / "serial" / "train", kind, index))
            two = read_shard(shard_path(tmp_path / "parallel" / "train", kind, index))
            assert set(one) == set(two)
            for key in one:
                if one[key].dtype.kind in "fc":
                    np.testing.assert_array_equal(one[key], two[key], err_msg=key)
                else:
                    assert np.array_equal(one[key], two[key]), key
    assert read_manifest(tmp_path / "parallel" / "train")["counts"] == {ARTICULATED: 4, FREE: 4}


def _rebuild_manifest(directory) -> dict:
    """Rewrite ``directory``'s manifest from its shards, with the config it was generated with."""
    from wpbench.data.manifest import build_manifest, write_manifest

    recorded = read_manifest(directory)["config"]
    config = GenerationConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in recorded.items()})
    manifest = build_manifest(directory, config)
    write_manifest(directory, manifest)
    return manifest


def test_content_hash_tells_apart_data_written_with_the_same_options(tmp_path):
    from wpbench.data.shards import write_shard

    for name in ("one", "two"):
        write_synthetic_split(tmp_path / name, "val", per_kind=3, num_action_points=16, num_anchor_points=24)
    # Same options, same fingerprint, other furniture: one free sample's anchor cloud moves.
    path = shard_path(tmp_path / "two" / "val", FREE, 0)
    arrays = read_shard(path)
    arrays["anchor_points"][1] += np.float32(0.05)
    write_shard(path, arrays)
    manifests = {name: _rebuild_manifest(tmp_path / name / "val") for name in ("one", "two")}
    assert manifests["one"]["fingerprint"] == manifests["two"]["fingerprint"]
    assert manifests["one"]["shards"][0] == manifests["two"]["shards"][0]  # the articulated shards are the same
    assert manifests["one"]["content_hash"] != manifests["two"]["content_hash"]
    for kinds in ((ARTICULATED, FREE), (FREE,)):
        one, two = (CrossPoseDataset(tmp_path / name / "val", kinds).content_hash for name in ("one", "two"))
        assert one != two, kinds
        assert one == CrossPoseDataset(tmp_path / "one" / "val", kinds).content_hash  # the same data, the same hash
    # A dataset of only the shards both sets share has one hash.
    assert (CrossPoseDataset(tmp_path / "one" / "val", (ARTICULATED,)).content_hash
            == CrossPoseDataset(tmp_path / "two" / "val", (ARTICULATED,)).content_hash)


def test_data_written_before_shards_stored_digests_loads_with_the_same_hashes(tmp_path):
    from wpbench.data.manifest import write_manifest
    from wpbench.data.shards import DIGEST_KEY, array_digest

    current = write_synthetic_split(tmp_path, "train", per_kind=3, num_action_points=16, num_anchor_points=24)
    hash_now = CrossPoseDataset(tmp_path / "train").content_hash
    for entry in current["shards"]:
        path = tmp_path / "train" / entry["path"]
        arrays = read_shard(path)
        assert entry["digest"] == str(arrays[DIGEST_KEY]) == array_digest(arrays)
        with open(path, "wb") as handle:  # an older shard: no digest inside
            np.savez_compressed(handle, **{k: v for k, v in arrays.items() if k != DIGEST_KEY})
    old_style = {**current, "shards": [{k: v for k, v in e.items() if k != "digest"} for e in current["shards"]]}
    write_manifest(tmp_path / "train", old_style)
    old = CrossPoseDataset(tmp_path / "train")
    assert len(old) == 6 and old.content_hash == hash_now
    assert _rebuild_manifest(tmp_path / "train")["content_hash"] == current["content_hash"]
