"""WeightedPose fine-tuning in two phases: first the mixing weight alone, then everything.

A WeightedPose variant starts from a converged Goal Flow and a converged
TAX-Pose, but its mixing-weight head is new (Goal Flow alone never uses w).
Training everything at once from there lets the gradients of a random w (0.5:
half flow, half correspondences, wrong for both kinds) move the trained
branches before w has learned which branch to trust, and the fused pose can end
worse on articulated objects than Goal Flow alone (measured in docs/experiment-log.md).

So the first ``fraction`` of the time budget trains only the mixing head with
both branches frozen (a step then costs about one forward pass: nothing
upstream of w needs gradients), and the rest trains every weight, from a w
that already separates the kinds.
"""

from __future__ import annotations

import torch

MIXING_HEAD = "goalflow.mixing_head."


def mixing_head_parameters(model: torch.nn.Module) -> list[str]:
    """Names of the parameters of WeightedPose's mixing-weight head (ValueError if it has none)."""
    names = [name for name, _ in model.named_parameters() if name.startswith(MIXING_HEAD)]
    if not names:
        raise ValueError(
            f"{type(model).__name__} has no mixing-weight head ({MIXING_HEAD}*): "
            "the mixing warm-up is for WeightedPose models only; set mixing_warmup to 0"
        )
    return names


def set_phase(model: torch.nn.Module, mixing_only: bool) -> None:
    """Freeze every parameter but the mixing head (``mixing_only``) or unfreeze them all."""
    head = set(mixing_head_parameters(model)) if mixing_only else set()
    for name, parameter in model.named_parameters():
        parameter.requires_grad_(not mixing_only or name in head)


def in_warmup(elapsed_s: float, budget_s: float, fraction: float) -> bool:
    """Whether a run ``elapsed_s`` into its ``budget_s`` is still in the mixing-only phase."""
    return fraction > 0 and elapsed_s < fraction * budget_s
