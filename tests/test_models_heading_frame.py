"""The heading frame (wpbench.models.heading_frame) against exact answers."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.models.heading_frame import from_heading_frame, heading_rotation, to_heading_frame


def _clouds(offset_xy, batch=1):
    anchor = torch.zeros(batch, 4, 3, dtype=torch.float64)
    anchor[:, :, 2] = torch.tensor([0.0, 1.0, 2.0, 3.0], dtype=torch.float64)
    action = torch.zeros(batch, 2, 3, dtype=torch.float64)
    action[:, :, 0], action[:, :, 1] = offset_xy[0], offset_xy[1]
    action[:, :, 2] = 5.0
    return action, anchor


@settings(max_examples=25, deadline=None)
@given(angle=st.floats(-math.pi, math.pi), distance=st.floats(0.01, 5.0))
def test_the_offset_lands_on_plus_x_and_z_is_kept(angle, distance):
    offset = (distance * math.cos(angle), distance * math.sin(angle))
    action, anchor = _clouds(offset)
    R = heading_rotation(action, anchor)
    mapped = R[0] @ torch.tensor([offset[0], offset[1], 0.0], dtype=torch.float64)
    assert torch.allclose(mapped, torch.tensor([distance, 0.0, 0.0], dtype=torch.float64), atol=1e-9)
    assert torch.allclose(R[0, 2], torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
    assert torch.allclose(R[0] @ R[0].T, torch.eye(3, dtype=torch.float64), atol=1e-12)
    assert torch.isclose(torch.linalg.det(R[0]), torch.tensor(1.0, dtype=torch.float64))


def test_a_vertical_offset_keeps_the_world_frame():
    action, anchor = _clouds((0.0, 0.0))
    assert torch.equal(heading_rotation(action, anchor)[0], torch.eye(3, dtype=torch.float64))


def test_to_and_from_are_inverse():
    action, anchor = _clouds((0.3, -0.4), batch=2)
    R = heading_rotation(action, anchor)
    points = torch.randn(2, 7, 3, dtype=torch.float64)
    assert torch.allclose(from_heading_frame(R, to_heading_frame(R, points)), points, atol=1e-12)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match=r"\(B, N, 3\)"):
        heading_rotation(torch.zeros(5, 3), torch.zeros(1, 5, 3))
