"""``identity``: does nothing. The lower bound."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from wpbench.policies.base import Policy, PolicyConfig, PolicyOutput


@dataclass
class IdentityConfig(PolicyConfig):
    name: ClassVar[str] = "identity"


class IdentityPolicy(Policy):
    def __init__(self, config: IdentityConfig | None = None):
        self.config = config or IdentityConfig()

    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        return PolicyOutput(np.eye(4))
