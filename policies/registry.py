"""Policies by name. Entries point at a module and a class, imported only when
asked for, so listing policies never loads torch.

To add a policy: write ``policies/<name>.py`` with a config dataclass and a
``Policy`` subclass, and add one line to ``POLICIES``.
"""

from __future__ import annotations

import importlib

from policies.base import Policy

# name -> "module:Class" (the class takes keyword arguments of its config)
POLICIES: dict[str, str] = {
    "gt": "policies.gt:GroundTruthPolicy",
    "identity": "policies.identity:IdentityPolicy",
    "gf": "policies.learned:GoalFlowPolicy",
    "tp": "policies.learned:TaxPosePolicy",
    "wp-og": "policies.learned:WeightedPoseOGPolicy",
    "wp-postsvd": "policies.learned:WeightedPosePostSVDPolicy",
    "wp-postsvd-t": "policies.learned:WeightedPosePostSVDTPolicy",
    "wp": "policies.learned:BestWeightedPosePolicy",
    "oracle": "policies.oracle:OraclePolicy",
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
