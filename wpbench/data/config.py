"""What ``wpbench data generate`` samples, as one typed config.

Kinds map to tasks (``wpbench.names.KIND_TASK``): ``articulated`` samples come from
``open-door``, ``free-floating`` ones from ``place-in``; each split (train / val)
uses only that split's furniture instances, so validation furniture is never
seen in training.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field

from wpbench.names import ARTICULATED, FREE, KIND_CODE, KIND_TASK, KINDS, OBS_MODES, SPLITS


@dataclass(frozen=True)
class GenerationConfig:
    """How to sample one split.

    samples_per_kind: samples of each kind (rounded up to whole shards).
    shard_size: samples per shard file; a multiple of ``scene_reuse``.
    scene_reuse: consecutive samples that share one loaded furniture instance
        (a scene load is the slow part of a reset); the furniture's pose, the
        start state and the camera still change with every sample.
    wide_start_probability: for articulated samples, the chance that the start
        joint value is redrawn uniformly in ``wide_start_fraction`` (fraction of the
        way from closed to open) instead of the task's own lower quarter, so the
        model also sees half-open doors. Validation keeps the task's distribution (0).
    objects: Ravens objects placed by the free-floating task.
    camera_noise: camera observations only: a real sensor's errors, the fields of
        ``wpbench.sim.camera_noise.CameraNoise`` that differ from a clean camera ({}).
    extra_train_instances: procedural furniture only: that many more train instances
        per category than the benchmark's library (12 train / 4 val), numbered after
        it, so the val furniture stays exactly the benchmark's and is never trained on.
    """

    split: str = "train"
    obs: str = "camera"
    seed: int = 0
    samples_per_kind: int = 1500
    kinds: tuple[str, ...] = KINDS
    shard_size: int = 50
    scene_reuse: int = 5
    wide_start_probability: float = 0.5
    wide_start_fraction: tuple[float, float] = (0.0, 0.9)
    objects: tuple[str, ...] = ("block",)
    num_action_points: int = 256
    num_anchor_points: int = 1024
    assets: str = "procedural"
    extra_train_instances: int = 0
    extra: dict = field(default_factory=dict)
    camera_noise: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {self.split!r}")
        if self.obs not in OBS_MODES:
            raise ValueError(f"obs must be one of {OBS_MODES}, got {self.obs!r}")
        unknown = [k for k in self.kinds if k not in KINDS]
        if unknown or not self.kinds:
            raise ValueError(f"kinds must be a non-empty subset of {KINDS}, got {self.kinds!r}")
        if self.samples_per_kind < 1 or self.shard_size < 1 or self.scene_reuse < 1:
            raise ValueError("samples_per_kind, shard_size and scene_reuse must be >= 1")
        if self.shard_size % self.scene_reuse:
            raise ValueError(
                f"shard_size ({self.shard_size}) must be a multiple of scene_reuse ({self.scene_reuse}) "
                "so every shard starts with a fresh scene (shards are then independent and reproducible)"
            )
        from wpbench.sim.camera_noise import CameraNoise

        noise = CameraNoise.from_settings(self.camera_noise)
        if self.obs != "camera" and not noise.is_clean:
            raise ValueError("camera noise needs obs='camera'")
        object.__setattr__(self, "camera_noise", noise.settings())  # frozen: only the normal form is kept
        if self.extra_train_instances < 0:
            raise ValueError(f"extra_train_instances must be >= 0, got {self.extra_train_instances}")
        if not 0.0 <= self.wide_start_probability <= 1.0:
            raise ValueError(f"wide_start_probability must be in [0, 1], got {self.wide_start_probability}")

    def shards_per_kind(self) -> int:
        return -(-self.samples_per_kind // self.shard_size)

    def sample_fingerprint(self) -> str:
        """Hash of every field that changes what a given sample contains.

        ``samples_per_kind`` and ``kinds`` only change how many shards exist, so
        they are left out: asking for more samples later extends a split.
        """
        d = asdict(self)
        for key in ("samples_per_kind", "kinds"):
            d.pop(key)
        if not d["extra_train_instances"]:
            d.pop("extra_train_instances")  # data made before the option existed keeps its fingerprint
        if not d["camera_noise"]:
            d.pop("camera_noise")  # likewise: a clean camera is what older data saw
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    def to_json(self) -> dict:
        d = asdict(self)
        d["kinds"] = list(self.kinds)
        d["wide_start_fraction"] = list(self.wide_start_fraction)
        d["objects"] = list(self.objects)
        return d
