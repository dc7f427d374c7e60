"""Policies by name. Entries point at a module and a class, imported only when
asked for, so listing policies never loads torch.

To add a policy: write ``policies/<name>.py`` with a config dataclass and a
``Policy`` subclass, and add one line to ``POLICIES``.
"""

from __future__ import annotations

import importlib

from wpbench.policies.base import Policy

# name -> "module:Class" (the class takes keyword arguments of its config)
POLICIES: dict[str, str] = {
    "gt": "wpbench.policies.gt:GroundTruthPolicy",
    "identity": "wpbench.policies.identity:IdentityPolicy",
    "gf": "wpbench.policies.learned:GoalFlowPolicy",
    "tp": "wpbench.policies.learned:TaxPosePolicy",
    "wp-og": "wpbench.policies.learned:WeightedPoseOGPolicy",
    "wp-postsvd": "wpbench.policies.learned:WeightedPosePostSVDPolicy",
    "wp-postsvd-t": "wpbench.policies.learned:WeightedPosePostSVDTPolicy",
    "wp": "wpbench.policies.learned:BestWeightedPosePolicy",
    "oracle": "wpbench.policies.oracle:OraclePolicy",
}


def available_policies() -> list[str]:
    return sorted(POLICIES)


def make_policy(name: str, **kwargs) -> Policy:
    """Build the policy called ``name``; ValueError listing the valid names otherwise."""
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}; valid: {', '.join(available_policies())}")
    module_name, class_name = POLICIES[name].split(":")
    cls = getattr(importlib.import_module(module_name), class_name)
    return cls(**kwargs)
