"""Mirrored views of the subset ensemble (``wpbench.models.subset_ensemble``): a scene answered
in its mirror image comes back as the same rigid motion, exactly."""

from __future__ import annotations

import numpy as np
import pytest
import roma
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.geometry import se3
from wpbench.models.subset_ensemble import MIRROR_Y, into_view, out_of_view, view_transforms

MIRROR = torch.diag(torch.tensor(MIRROR_Y, dtype=torch.float64))


def _rigid(batch: int, generator: torch.Generator) -> torch.Tensor:
    t = torch.randn(batch, 3, generator=generator, dtype=torch.float64)
    return se3.make_transform(roma.random_rotmat(batch, dtype=torch.float64), t)


def test_every_second_view_is_the_mirror_and_the_first_is_the_scene_as_observed():
    views = view_transforms(5, mirror=True)
    for k in range(5):
        torch.testing.assert_close(views[k], MIRROR if k % 2 else torch.eye(4, dtype=torch.float64), atol=0, rtol=0)
    torch.testing.assert_close(view_transforms(3, mirror=False), torch.eye(4, dtype=torch.float64).repeat(3, 1, 1))
    assert torch.linalg.det(views[1, :3, :3]) == -1.0  # a reflection, not a rotation
    with pytest.raises(ValueError, match="count"):
        view_transforms(0, mirror=True)


@given(seed=st.integers(0, 2**31 - 1))
@settings(max_examples=50, deadline=None)
def test_an_answer_given_in_the_mirrored_scene_comes_back_as_the_true_motion(seed):
    # A perfect model sees the mirrored cloud M p and answers the mirrored motion M T M: its goal
    # is M (T p). Back out of the view it must be T itself, a proper rigid motion.
    g = torch.Generator().manual_seed(seed)
    T = _rigid(2, g)
    points = torch.randn(2, 20, 3, generator=g, dtype=torch.float64)
    views = view_transforms(2, mirror=True)
    seen = into_view(points[None].expand(2, -1, -1, -1), views)
    torch.testing.assert_close(seen[1], points * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64))
    answers = torch.stack([views[k] @ T @ views[k] for k in range(2)])  # (K, B, 4, 4)
    torch.testing.assert_close(se3.apply(answers[1], seen[1]), se3.apply(T, points) * torch.tensor([1.0, -1.0, 1.0],
                                                                                                    dtype=torch.float64))
    back = out_of_view(answers, views)
    torch.testing.assert_close(back, T.expand(2, -1, -1, -1), atol=1e-12, rtol=0)
    assert torch.allclose(torch.linalg.det(back[..., :3, :3]), torch.ones(2, 2, dtype=torch.float64))


@given(seed=st.integers(0, 2**31 - 1))
@settings(max_examples=30, deadline=None)
def test_a_wrong_answer_in_the_mirror_stays_rigid_and_moves_no_more_than_it_did(seed):
    g = torch.Generator().manual_seed(seed)
    T = _rigid(3, g)
    back = out_of_view(T[None], view_transforms(2, mirror=True)[1:])[0]
    R = back[:, :3, :3]
    torch.testing.assert_close(R @ R.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(3, -1, -1))
    assert torch.allclose(torch.linalg.det(R), torch.ones(3, dtype=torch.float64))
    # The reflection keeps angles and lengths: the same turn, the same distance.
    angle = lambda M: roma.rotmat_geodesic_distance(M[:, :3, :3], torch.eye(3, dtype=M.dtype).expand(len(M), -1, -1))  # noqa: E731
    torch.testing.assert_close(angle(back), angle(T))
    torch.testing.assert_close(back[:, :3, 3].norm(dim=1), T[:, :3, 3].norm(dim=1))


def test_views_refuse_mismatched_shapes():
    views = view_transforms(2, mirror=True)
    with pytest.raises(ValueError, match="views"):
        into_view(torch.zeros(3, 5, 3), views)
    with pytest.raises(ValueError, match="views"):
        out_of_view(torch.zeros(2, 4, 3), views)
    with pytest.raises(ValueError, match="views"):
        out_of_view(torch.eye(4).repeat(2, 1, 1), views[0])
    np.testing.assert_array_equal(into_view(torch.ones(2, 4, 3), views)[1].numpy(), np.tile([1.0, -1.0, 1.0], (4, 1)))
