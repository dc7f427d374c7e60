"""Loss presets: which loss terms train which policy, with their weights in one place.

Each preset is one frozen ``LossPreset`` in ``LOSS_PRESETS``; a weight of 0
leaves the term out (it is not even computed). The WeightedPose presets are
the three rows of the paper's table:

- ``wp-og``: the original TAX-Pose losses, as TAX-Pose applies them to its own
  final SVD pose, here to WeightedPose's fused pose (point displacement and
  correspondence consistency), plus direct supervision of the intermediate
  predictions: TAX-Pose's correspondences and Goal Flow's flow. The fused pose
  is what trains the mixing weight w (with the displacement term on the
  TAX-Pose branch alone, w would get no gradient at all).
- ``wp-postsvd``: only the point loss after the final, fused weighted SVD
  (trains both branches and w end to end).
- ``wp-postsvd-t``: post-SVD point loss + a direct SE(3) loss on the fused pose.

and the baselines ``tp`` (TAX-Pose losses on its pose) and ``gf`` (flow
supervision, as FlowBot3D trains its flow).

Weight scales: the point terms are in m^2. The rotation term
``|R - R_gt|_F^2`` is unitless; its weight 0.05 m^2 = (22 cm)^2 makes a rotation cost
about what it moves the surface of a 22 cm object, so the 16 cm block's tilt, which the
point terms barely see, is paid for. The translation term (the goal position of the
action centroid, m^2) weighs 3. How these weights compare with others on val is in
docs/experiment-log.md ("wp-postsvd-t's loss weights").
TAX-Pose's terms use displacement 1, direct correspondence 1, consistency 0.1
(the consistency term is a regulariser; the first two carry the supervision).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Literal

import torch

from wpbench.data.equivalent_goals import nearest_goal
from wpbench.models import losses
from wpbench.models.output import CrossPoseOutput

PoseForTaxPoseTerms = Literal["output", "taxpose_branch"]

# A symmetric object's other goals count only once the output is this close to one of them
# (the default; a policy can choose its own, ``wpbench.training.specs``). 180 = every goal counts:
# the nearest equivalent goal is always the target. A smaller gate makes the target flip where the
# stored goal flips (a cube's at a 45 deg turn), and the network learns the average of both sides
# (measured in docs/experiment-log.md, "The block's rotation tail: no symmetric-goal gate").
RETARGET_WITHIN_DEG = 180.0


@dataclass(frozen=True)
class LossPreset:
    """Weights of every loss term (0 = not used).

    taxpose_pose: the pose that the TAX-Pose displacement and consistency
        terms compare against: the model's output, or WeightedPose's
        TAX-Pose branch alone (``diagnostics["taxpose_transform"]``).
    """

    name: str
    taxpose_pose: PoseForTaxPoseTerms = "output"
    point_displacement: float = 0.0
    direct_correspondence: float = 0.0
    correspondence_consistency: float = 0.0
    goal_flow: float = 0.0
    post_svd_point: float = 0.0
    rotation: float = 0.0
    translation: float = 0.0

    def __post_init__(self) -> None:
        if self.taxpose_pose not in ("output", "taxpose_branch"):
            raise ValueError(f"taxpose_pose must be 'output' or 'taxpose_branch', got {self.taxpose_pose!r}")
        # comparisons with NaN are false, so NaN fails too (it would make every step non-finite and skipped)
        if not all(0 <= weight < float("inf") for weight in self.weights.values()):
            raise ValueError(f"loss weights must be finite and >= 0, got {self.weights}")
        if not any(self.weights.values()):
            raise ValueError(f"loss preset {self.name!r} has no term with a positive weight")

    @property
    def weights(self) -> dict[str, float]:
        """Term name -> weight, for every term (including zero weights)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("name", "taxpose_pose")}

    @property
    def terms(self) -> tuple[str, ...]:
        """Names of the terms this preset uses (positive weight)."""
        return tuple(name for name, weight in self.weights.items() if weight > 0)


LOSS_PRESETS: dict[str, LossPreset] = {
    preset.name: preset
    for preset in (
        LossPreset(
            name="tp",
            taxpose_pose="output",
            point_displacement=1.0,
            direct_correspondence=1.0,
            correspondence_consistency=0.1,
        ),
        LossPreset(name="gf", goal_flow=1.0),
        LossPreset(
            name="wp-og",
            taxpose_pose="output",
            point_displacement=1.0,
            direct_correspondence=1.0,
            correspondence_consistency=0.1,
            goal_flow=1.0,
        ),
        LossPreset(name="wp-postsvd", post_svd_point=1.0),
        LossPreset(name="wp-postsvd-t", post_svd_point=1.0, rotation=0.05, translation=3.0),
    )
}


def get_preset(preset: str | LossPreset) -> LossPreset:
    """A preset by name (or the preset itself)."""
    if isinstance(preset, LossPreset):
        return preset
    if preset not in LOSS_PRESETS:
        raise ValueError(f"unknown loss preset {preset!r}; choose one of {sorted(LOSS_PRESETS)}")
    return LOSS_PRESETS[preset]


def _check_batch(output: CrossPoseOutput, batch: dict[str, torch.Tensor]) -> None:
    missing = [key for key in ("action", "anchor", "gt_transform") if key not in batch]
    if missing:
        raise ValueError(f"batch lacks {missing}; it needs action (B,NA,3), anchor (B,NB,3), gt_transform (B,4,4)")
    B = output.transform.shape[0]
    if batch["gt_transform"].shape != (B, 4, 4):
        raise ValueError(f"gt_transform must have shape (B, 4, 4) = {(B, 4, 4)}, got {tuple(batch['gt_transform'].shape)}")
    for key in ("action", "anchor"):
        if batch[key].dim() != 3 or batch[key].shape[0] != B or batch[key].shape[-1] != 3:
            raise ValueError(f"batch[{key!r}] must have shape (B, N, 3) with B = {B}, got {tuple(batch[key].shape)}")


def compute_loss(
    output: CrossPoseOutput,
    batch: dict[str, torch.Tensor],
    preset: str | LossPreset,
    retarget_within_deg: float = RETARGET_WITHIN_DEG,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Total loss and its named, unweighted terms (detached, for logging).

    output: the model's CrossPoseOutput for ``batch["action"]``, ``batch["anchor"]``.
    batch: ``action`` (B,NA,3), ``anchor`` (B,NB,3), ``gt_transform`` (B,4,4), and optionally
    ``gt_equivalents`` (B,K,4,4): then every term compares against the equivalent goal nearest
    to the output among those within ``retarget_within_deg`` of it, else the stored goal (a
    symmetric object's goals are all correct; see ``equivalent_goals``).
    Raises ValueError if the model lacks a diagnostic the preset needs
    (e.g. ``tp`` on a Goal Flow model).
    """
    preset = get_preset(preset)
    _check_batch(output, batch)
    action, anchor, T_gt = batch["action"], batch["anchor"], batch["gt_transform"].to(output.transform.dtype)
    T_out = output.transform
    if "gt_equivalents" in batch:
        T_gt = nearest_goal(T_out, batch["gt_equivalents"], within_deg=retarget_within_deg).to(T_out.dtype)
    T_tax = output.require("taxpose_transform") if preset.taxpose_pose == "taxpose_branch" else T_out

    term_functions = {
        "point_displacement": lambda: losses.point_displacement_loss(T_tax, T_gt, action),
        "direct_correspondence": lambda: losses.direct_correspondence_loss(
            action, output.require("action_targets"), anchor, output.require("anchor_sources"), T_gt
        ),
        "correspondence_consistency": lambda: losses.correspondence_consistency_loss(
            T_tax, action, output.require("action_targets"), anchor, output.require("anchor_sources")
        ),
        "goal_flow": lambda: losses.goal_flow_loss(output.require("flow"), action, T_gt),
        "post_svd_point": lambda: losses.post_svd_point_loss(T_out, T_gt, action),
        "rotation": lambda: losses.rotation_loss(T_out, T_gt),
        "translation": lambda: losses.translation_loss(T_out, T_gt, action.mean(dim=1)),
    }
    total = T_out.new_zeros(())
    terms: dict[str, torch.Tensor] = {}
    for name in preset.terms:
        value = term_functions[name]()
        total = total + preset.weights[name] * value
        terms[name] = value.detach()
    return total, terms
