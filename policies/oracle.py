"""``oracle``: the switcher that knows the kind of goal (articulated or free-floating)
from the ground truth and calls Goal Flow (``gf``) or TAX-Pose (``tp``) accordingly.

It shows how far one could get by picking the right specialist every time,
the bound WeightedPose's learned mixing weight is compared against.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from wpbench.names import ARTICULATED, KINDS
from wpbench.policies.base import Policy, PolicyConfig, PolicyOutput
from wpbench.models.configs import DEFAULT_MIRROR_VIEWS, DEFAULT_SUBSETS



@dataclass
class OracleConfig(PolicyConfig):
    name: ClassVar[str] = "oracle"
    articulated_policy: str = "gf"
    free_policy: str = "tp"
    weights_root: Path | None = None
    subsets: int = DEFAULT_SUBSETS  # passed to both experts (policies.learned), as is mirror_views
    mirror_views: bool = DEFAULT_MIRROR_VIEWS


class OraclePolicy(Policy):
    uses_ground_truth = True

    def __init__(self, config: OracleConfig | None = None, **kwargs: Any) -> None:
        from wpbench.policies.learned import LearnedPolicy

        self.config = config or OracleConfig(**kwargs)
        shared = {"weights_root": self.config.weights_root, "subsets": self.config.subsets,
                  "mirror_views": self.config.mirror_views}
        self.experts = {
            kind: LearnedPolicy(policy=self.config.articulated_policy if kind == ARTICULATED else self.config.free_policy,
                                **shared)
            for kind in KINDS
        }

    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        kind = (info or {}).get("kind")
        if kind not in KINDS:
            raise ValueError(f"oracle needs the ground-truth kind in info['kind'] (one of {', '.join(KINDS)}), "
                             f"got {kind!r}: give it the env's ground_truth()")
        out = self.experts[kind].predict(obs)
        out.diagnostics["oracle_choice"] = kind
        return out

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["experts"] = {kind: expert.describe() for kind, expert in self.experts.items()}
        return d
