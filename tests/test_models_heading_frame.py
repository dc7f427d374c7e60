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


def _panel(yaw: float, centre_xy=(0.0, 0.0), width=0.6, depth_offset=0.2):
    """A vertical panel (a door seen from the front) whose outward normal is at ``yaw``,
    ``depth_offset`` in front of a box anchor, and shifted sideways by ``centre_xy``."""
    normal = torch.tensor([math.cos(yaw), math.sin(yaw)], dtype=torch.float64)
    along = torch.tensor([-math.sin(yaw), math.cos(yaw)], dtype=torch.float64)
    s = torch.linspace(-width / 2, width / 2, 9, dtype=torch.float64)
    z = torch.linspace(0.0, 1.0, 5, dtype=torch.float64)
    ss, zz = torch.meshgrid(s, z, indexing="ij")
    base = torch.tensor(centre_xy, dtype=torch.float64) + depth_offset * normal
    xy = base + ss.reshape(-1, 1) * along
    action = torch.cat([xy, zz.reshape(-1, 1)], dim=1)[None]
    anchor = torch.zeros(1, 4, 3, dtype=torch.float64)
    anchor[0, :, 2] = torch.tensor([0.0, 0.3, 0.6, 0.9], dtype=torch.float64)
    return action, anchor, normal


@settings(max_examples=25, deadline=None)
@given(yaw=st.floats(-math.pi, math.pi), sideways=st.floats(-0.25, 0.25))
def test_the_action_panel_heading_is_the_panels_outward_normal(yaw, sideways):
    """Even when the panel sits far to one side (the centroid direction is then tens of degrees off)."""
    along = (-math.sin(yaw) * sideways, math.cos(yaw) * sideways)
    action, anchor, normal = _panel(yaw, centre_xy=along)
    R = heading_rotation(action, anchor, source="action_panel")
    mapped = R[0, :2, :2] @ normal
    assert torch.allclose(mapped, torch.tensor([1.0, 0.0], dtype=torch.float64), atol=1e-9)
    assert torch.isclose(torch.linalg.det(R[0]), torch.tensor(1.0, dtype=torch.float64))


def test_an_unknown_heading_source_is_refused():
    action, anchor = _clouds((0.3, 0.1))
    with pytest.raises(ValueError, match="centroids"):
        heading_rotation(action, anchor, source="camera")


def test_goal_flow_config_refuses_an_unknown_heading_source():
    from wpbench.models.configs import GoalFlowConfig

    with pytest.raises(ValueError, match="action_panel"):
        GoalFlowConfig(heading_source="camera")
