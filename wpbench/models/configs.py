"""Typed configurations of the cross-pose models, free of torch imports.

Kept apart from the modules so that listing models or validating a config
(CLI, policy registry) does not pay for importing torch.

Default sizes are chosen for a laptop CPU (``wpbench bench models`` compares
them): the reference TAX-Pose uses DGCNN widths (64, 64, 128, 256), 512-dim
embeddings and k = 20 neighbours on 200 + 1800 points, too slow to train on
2 cores (costs in docs/models.md). wpbench keeps the architecture (dynamic-graph edge convolutions, cross-attention, soft
correspondences, residual flow, weighted SVD) and shrinks widths and k.
``<Config>.reference()`` gives the reference size for comparison.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

MixingWeightMode = Literal["per_sample", "per_point"]
# Directions the heading frame can put on +x (``wpbench.models.heading_frame``).
HeadingSource = Literal["centroids", "action_panel"]
HEADING_SOURCES: tuple[str, ...] = ("centroids", "action_panel")
# Random point subsets a learned policy answers and fuses into one pose (``wpbench.models.subset_ensemble``).
DEFAULT_SUBSETS = 8
# Answer every second subset in the mirrored scene (``wpbench.models.subset_ensemble.view_transforms``).
DEFAULT_MIRROR_VIEWS = True


@dataclass(frozen=True)
class DGCNNConfig:
    """A DGCNN point encoder.

    k: neighbours per point (the cloud needs more than k points).
    edge_channels: output width of each edge convolution; their outputs are
        concatenated and mixed by a pointwise layer into ``emb_dim``.
    dynamic_graph: recompute the kNN graph in feature space before every edge
        convolution after the first (DGCNN's "dynamic" graph); the first always
        uses xyz. False (the laptop default) keeps the xyz graph throughout:
        the feature-space kNN (a (N, N) distance matrix and a top-k per layer)
        is a large share of a step's cost on a CPU (docs/models.md). The
        reference size keeps the dynamic graph.
    groups: GroupNorm groups (normalisation is per sample, so a sample's output
        never depends on the rest of the batch).
    """

    k: int = 16
    edge_channels: tuple[int, ...] = (32, 32, 64, 64)
    emb_dim: int = 128
    dynamic_graph: bool = False
    groups: int = 4

    def __post_init__(self) -> None:
        if self.k < 1:
            raise ValueError(f"DGCNNConfig.k must be >= 1, got {self.k}")
        if not self.edge_channels or any(c < 1 for c in self.edge_channels):
            raise ValueError(f"DGCNNConfig.edge_channels must be positive widths, got {self.edge_channels}")
        for width in (*self.edge_channels, self.emb_dim):
            if width % self.groups:
                raise ValueError(
                    f"every DGCNN width must be divisible by groups={self.groups}, got {width}; "
                    "change edge_channels/emb_dim or groups"
                )

    @classmethod
    def reference(cls) -> DGCNNConfig:
        """The DGCNN of DCP/TAX-Pose: widths (64, 64, 128, 256), 512-dim, k = 20."""
        return cls(k=20, edge_channels=(64, 64, 128, 256), emb_dim=512, dynamic_graph=True, groups=8)


@dataclass(frozen=True)
class TaxPoseConfig:
    """TAX-Pose: one DGCNN per object, cross-attention both ways, soft correspondences.

    attention_layers/heads/ffn_mult: the cross-attention transformer (width = encoder emb_dim).
    head_hidden: hidden width of the per-point residual-flow + weight head.
    heading_frame: run the network in the scene's heading frame
        (``wpbench.models.heading_frame``): exact yaw equivariance.
    learn_sharpness: learn a factor on the correspondence scores (softmax
        temperature), so the soft correspondences can sharpen quickly.
    absolute_height: centre each cloud only horizontally before its encoder, so
        the features see heights above the floor (z = 0): which shelf of a
        cabinet the block goes on depends on its height above the floor, which a
        cloud centred on its own centroid shows only through the furniture's
        lowest points. Equivariance to horizontal translation and yaw is kept;
        a vertical shift of the whole scene is no longer one the model ignores.
    """

    encoder: DGCNNConfig = field(default_factory=DGCNNConfig)
    attention_layers: int = 1
    attention_heads: int = 4
    ffn_mult: int = 2
    head_hidden: int = 64
    heading_frame: bool = True
    learn_sharpness: bool = True
    absolute_height: bool = False

    def __post_init__(self) -> None:
        if self.encoder.emb_dim % self.attention_heads:
            raise ValueError(
                f"encoder.emb_dim={self.encoder.emb_dim} must be divisible by attention_heads={self.attention_heads}"
            )
        if self.attention_layers < 1:
            raise ValueError("TaxPoseConfig.attention_layers must be >= 1")

    @classmethod
    def reference(cls) -> TaxPoseConfig:
        """TAX-Pose at its published size (512-dim DGCNN embeddings, 4 heads)."""
        return cls(encoder=DGCNNConfig.reference(), attention_layers=1, attention_heads=4, ffn_mult=2, head_hidden=256)


@dataclass(frozen=True)
class GoalFlowConfig:
    """Goal Flow: one DGCNN over action ∪ anchor (xyz + "is action" channel).

    mixing_weight: shape of the mixing weight w its head predicts for
        WeightedPose: one per sample (the paper) or one per action point.
    position_scale: factor on the centred action xyz fed to the flow head
        (1 / typical object size in metres), so it sees unit-scale inputs.
    heading_frame: run the network in the scene's heading frame
        (``wpbench.models.heading_frame``): exact yaw equivariance.
    affine_flow: add a per-sample affine flow ``M p + b`` (from the global
        feature) to the per-point flow: a rigid motion's flow is exactly that.
    heading_source: the direction the heading frame puts on +x: "action_panel"
        (the normal of the action's footprint, the default) or "centroids"
        (anchor -> action); see ``wpbench.models.heading_frame``.
    anchor_extent: give the flow heads the anchor's bounding box (its min and max
        corner, relative to the action centroid, in the heading frame) next to
        the max-pooled feature: how far a drawer slides or where a hinge sits
        depends on the furniture's size, which max-pooled point features
        measure poorly (see ``GoalFlow``).
    The two defaults changed (``GOALFLOW_FIELDS_BEFORE_DEFAULT_CHANGE``); the
    comparison behind them is ``results/experiments/README.md``.
    """

    encoder: DGCNNConfig = field(default_factory=DGCNNConfig)
    head_hidden: int = 64
    mixing_weight: MixingWeightMode = "per_sample"
    position_scale: float = 10.0
    heading_frame: bool = True
    affine_flow: bool = True
    anchor_extent: bool = True
    heading_source: HeadingSource = "action_panel"

    def __post_init__(self) -> None:
        if self.heading_source not in HEADING_SOURCES:
            raise ValueError(f"heading_source must be one of {HEADING_SOURCES}, got {self.heading_source!r}")
        if self.mixing_weight not in ("per_sample", "per_point"):
            raise ValueError(f"mixing_weight must be 'per_sample' or 'per_point', got {self.mixing_weight!r}")
        if not self.position_scale > 0:
            raise ValueError(f"position_scale must be > 0, got {self.position_scale}")

    @classmethod
    def reference(cls) -> GoalFlowConfig:
        """Goal Flow with the reference DGCNN (512-dim embeddings)."""
        return cls(encoder=DGCNNConfig.reference(), head_hidden=256)


# Values a saved Goal Flow config.json without these keys was trained with; they differ
# from the defaults above (``wpbench.models.registry.saved_model_config``).
GOALFLOW_FIELDS_BEFORE_DEFAULT_CHANGE: dict[str, Any] = {"anchor_extent": False, "heading_source": "centroids"}


@dataclass(frozen=True)
class WeightedPoseConfig:
    """WeightedPose = Goal Flow + TAX-Pose, fused by one weighted SVD.

    w_mode: one mixing weight per sample (the paper) or per action point.
        It is the single source of truth: the Goal Flow branch is built with
        ``mixing_weight = w_mode`` whatever ``goalflow.mixing_weight`` says.
    """

    goalflow: GoalFlowConfig = field(default_factory=GoalFlowConfig)
    taxpose: TaxPoseConfig = field(default_factory=TaxPoseConfig)
    w_mode: MixingWeightMode = "per_sample"

    def __post_init__(self) -> None:
        if self.w_mode not in ("per_sample", "per_point"):
            raise ValueError(f"w_mode must be 'per_sample' or 'per_point', got {self.w_mode!r}")

    @property
    def goalflow_branch(self) -> GoalFlowConfig:
        """The Goal Flow config actually built (mixing weight shape from ``w_mode``)."""
        return dataclasses.replace(self.goalflow, mixing_weight=self.w_mode)

    @classmethod
    def reference(cls) -> WeightedPoseConfig:
        return cls(goalflow=GoalFlowConfig.reference(), taxpose=TaxPoseConfig.reference())


ModelConfig = TaxPoseConfig | GoalFlowConfig | WeightedPoseConfig


def apply_overrides(config: Any, overrides: dict[str, Any]) -> Any:
    """Return ``config`` with ``overrides`` applied; nested configs take dicts.

    ``apply_overrides(WeightedPoseConfig(), {"taxpose": {"encoder": {"k": 8}}})``
    changes only k of the TAX-Pose encoder. Lists become tuples (JSON friendly).
    """
    if not dataclasses.is_dataclass(config):
        raise TypeError(f"expected a config dataclass instance, got {type(config).__name__}")
    valid = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(overrides) - valid)
    if unknown:
        raise ValueError(
            f"unknown option(s) {unknown} for {type(config).__name__}; valid options: {sorted(valid)}"
        )
    changes: dict[str, Any] = {}
    for name, value in overrides.items():
        current = getattr(config, name)
        if dataclasses.is_dataclass(current) and isinstance(value, dict):
            value = apply_overrides(current, value)
        elif isinstance(value, list):
            value = tuple(value)
        changes[name] = value
    return dataclasses.replace(config, **changes)
