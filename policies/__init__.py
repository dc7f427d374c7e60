"""wpbench policies: one file per policy, found by name in ``policies.registry``."""

from wpbench.policies.registry import available_policies, make_policy

__all__ = ["available_policies", "make_policy"]
