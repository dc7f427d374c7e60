"""DGCNN building blocks: kNN, the neighbour max and the edge-convolution rewrite."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wpbench.models.configs import DGCNNConfig
from wpbench.models.dgcnn import DGCNN, EdgeConv, gather_neighbours, knn_indices, max_over_neighbours


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), points=st.integers(9, 60), k=st.integers(1, 8))
def test_knn_matches_brute_force(seed, points, k):
    x = torch.randn(2, points, 5, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    expected = torch.cdist(x, x).argsort(dim=-1)[..., :k]
    got = knn_indices(x, k)
    assert torch.equal(got.sort(dim=-1).values, expected.sort(dim=-1).values)


def test_knn_rejects_too_few_points():
    with pytest.raises(ValueError, match="k=8"):
        knn_indices(torch.randn(1, 5, 3), 8)


def test_max_over_neighbours_matches_gather_amax_with_gradients():
    torch.manual_seed(0)
    values = torch.randn(3, 30, 6, dtype=torch.float64, requires_grad=True)
    indices = torch.randint(0, 30, (3, 20, 4))
    reference = gather_neighbours(values, indices).amax(dim=2)
    pooled = max_over_neighbours(values, indices)
    assert torch.equal(pooled, reference)
    with torch.no_grad():
        assert torch.equal(max_over_neighbours(values, indices), reference)
    assert torch.autograd.gradcheck(lambda v: max_over_neighbours(v, indices), (values,))


def test_edge_conv_equals_reference_edge_convolution():
    """act(max_j (A x_j) + C x_i + b) == max_j act(W [x_j - x_i; x_i] + b) with A = W1, C = W2 - W1."""
    torch.manual_seed(0)
    conv = EdgeConv(4, 8, groups=2).double()
    x = torch.randn(2, 25, 4, dtype=torch.float64)
    neighbours = knn_indices(x[..., :3], 6)
    W1, W2 = torch.randn(8, 4, dtype=torch.float64), torch.randn(8, 4, dtype=torch.float64)
    with torch.no_grad():
        conv.neighbour_map.weight.copy_(W1)
        conv.centre_map.weight.copy_(W2 - W1)
    conv.norm = torch.nn.Identity()  # compare the convolution itself; the norm comes after the max
    centre = x.unsqueeze(2).expand(-1, -1, 6, -1)
    edges = torch.cat([gather_neighbours(x, neighbours) - centre, centre], dim=-1)  # (B, N, k, 8)
    W = torch.cat([W1, W2], dim=1)
    reference = torch.nn.functional.leaky_relu(edges @ W.T + conv.centre_map.bias, 0.2).amax(dim=2)
    assert torch.allclose(conv(x, neighbours), reference, atol=1e-12)


@pytest.mark.parametrize("dynamic", [False, True])
def test_dgcnn_is_permutation_equivariant(dynamic):
    torch.manual_seed(0)
    encoder = DGCNN(DGCNNConfig(k=6, edge_channels=(8, 8), emb_dim=16, dynamic_graph=dynamic, groups=4)).double()
    x = torch.randn(2, 40, 3, dtype=torch.float64)
    permutation = torch.randperm(40)
    assert torch.allclose(encoder(x)[:, permutation], encoder(x[:, permutation]), atol=1e-10)


def test_dgcnn_requires_declared_features():
    encoder = DGCNN(DGCNNConfig(k=4, edge_channels=(8,), emb_dim=8, groups=4), extra_features=1)
    with pytest.raises(ValueError, match=r"\(B, N, 1\)"):
        encoder(torch.randn(1, 10, 3))


def test_config_rejects_widths_not_divisible_by_groups():
    with pytest.raises(ValueError, match="divisible"):
        DGCNNConfig(edge_channels=(30,), groups=4)
