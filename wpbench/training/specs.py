"""What each trainable policy is: model, loss preset, the data it sees, where it starts.

The baselines are trained on one kind each (Goal Flow on articulated data,
TAX-Pose on free-floating data, as in the paper's table); the WeightedPose
variants on both kinds, starting from the trained baselines' weights.
"""

from __future__ import annotations

from dataclasses import dataclass

from wpbench.names import ARTICULATED, FREE, TRAINABLE_POLICIES, WEIGHTED_POSE_VARIANTS
from wpbench.models.loss_presets import RETARGET_WITHIN_DEG


@dataclass(frozen=True)
class PolicySpec:
    name: str
    model: str                       # wpbench.models.registry name
    loss_preset: str                 # wpbench.models.loss_presets name
    kinds: tuple[str, ...]           # data kinds it trains and validates on
    starts_from: tuple[str, ...] = ()  # policies whose trained weights initialise it
    learning_rate: float = 1e-3
    # WeightedPose: fraction of the time budget that trains only the mixing-weight head
    # (branches frozen), at ``mixing_learning_rate``; see ``wpbench.training.warmup``.
    mixing_warmup: float = 0.0
    mixing_learning_rate: float = 1e-3
    # Random scene scale in [1 - s, 1 + s] (``wpbench.data.augment.random_scale``). On for the
    # policies that see furniture motion: it ties a drawer's travel to the chest's size. Off for
    # TAX-Pose, whose shipped weights are trained without it (its block is always the same 16 cm cube).
    augment_scale: float = 0.0
    # Random stretch of drawer samples along their slide (``random_slide_stretch``): "deeper chest,
    # longer slide", which the uniform scale does not teach (a chest's depth is drawn on its own).
    # On for gf and the WeightedPose variants, as their shipped weights are trained; TAX-Pose never
    # sees a drawer move. Its effect is measured in docs/experiment-log.md ("Slide stretch").
    augment_stretch: float = 0.0
    # A symmetric object's other equivalent goals become the training target once the prediction
    # is within this angle of one of them (``loss_presets.compute_loss``); 180 = always the nearest
    # (why: ``loss_presets.RETARGET_WITHIN_DEG``; measured in docs/experiment-log.md).
    retarget_within_deg: float = RETARGET_WITHIN_DEG


def _weighted_pose(name: str) -> PolicySpec:
    """A WeightedPose variant: both kinds, from the trained gf and tp, its own loss preset."""
    return PolicySpec(name, "weightedpose", name, (ARTICULATED, FREE), ("gf", "tp"), learning_rate=1e-4,
                      mixing_warmup=0.25, augment_scale=0.15, augment_stretch=0.25)


POLICY_SPECS: dict[str, PolicySpec] = {
    spec.name: spec
    for spec in (
        PolicySpec("gf", "goalflow", "gf", (ARTICULATED,), augment_scale=0.15, augment_stretch=0.25),
        PolicySpec("tp", "taxpose", "tp", (FREE,)),
        *(_weighted_pose(name) for name in WEIGHTED_POSE_VARIANTS),
    )
}
if tuple(POLICY_SPECS) != TRAINABLE_POLICIES:
    raise ImportError(f"wpbench.training.specs describes {tuple(POLICY_SPECS)}, but wpbench.names lists "
                      f"{TRAINABLE_POLICIES} as trainable: make them the same")


def get_spec(name: str) -> PolicySpec:
    if name not in POLICY_SPECS:
        raise ValueError(f"unknown trainable policy {name!r}; choose one of {', '.join(POLICY_SPECS)}")
    return POLICY_SPECS[name]
