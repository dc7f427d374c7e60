"""How one training run goes, as a typed config (saved in ``config.json``)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

from wpbench.weights import shipped_weights_root

# Where a training writes when no --out is given: ``runs/train/<policy>/`` (relative to the
# working directory). Runs are shipped into policies/weights/ only by ``wpbench train --promote``.
RUNS_ROOT = Path("runs") / "train"


def default_run_dir(policy: str) -> Path:
    """The run folder of ``policy`` when no --out is given."""
    return RUNS_ROOT / policy


@dataclass
class TrainConfig:
    """A training run of ``policy`` on ``data`` for at most ``minutes`` of wall time.

    data: a data root (train/ and val/ from ``wpbench data generate``), or several to mix:
        a list of paths, "PATH:WEIGHT" strings or ``DataSource`` s (``wpbench.training.data_mix``).
        After construction ``data`` is the first set's path (whose val/ selects the model) and
        ``data_sources`` every set with its weight.

    out: the run folder it writes [default: ``runs/train/<policy>``]; never the shipped weights
        unless asked for (``wpbench.weights.promote`` ships a finished run).
    weights_root: where the trained Goal Flow and TAX-Pose a WeightedPose variant starts from
        are read [default: the shipped ``policies/weights``; ``runs/train`` to start from runs].

    minutes: wall-time budget of the training epochs (steps, validations, checkpoints and
        logs), summed over resumed runs; the final validation runs after it.
    steps: optional budget in optimiser steps. With it, the learning-rate schedule and the
        mixing warm-up run over steps instead of seconds and the run ends after ``steps``,
        so its result does not depend on what else shares the machine (``minutes`` stays
        a wall-time cap). Used to give every WeightedPose variant the same compute.
    max_steps: optional cap on optimiser steps that leaves the schedule alone (tests use 2).
    steps_per_epoch: optimiser steps between validations / checkpoints (an "epoch"
        here is this many steps, so a run that cannot see all data still logs
        and checkpoints regularly).
    num_action_points / num_anchor_points: points per cloud the model trains on,
        a random subset of the stored clouds (cheaper; the policy subsamples its
        observations to the same counts).
    val_per_kind: validation samples per kind checked after every epoch;
        final_val_per_kind: for the final metrics.
    learning_rate: None = the policy's default (``specs``).
    mixing_warmup: WeightedPose only: fraction of the budget that trains the mixing
        head alone (``wpbench.training.warmup``); None = the policy's default.
    lr_schedule: "constant", or "cosine": decays from the learning rate to 5% of it
        over the budget (over ``steps`` when given, else over ``minutes``).
    model_overrides: changes to the model's default config (baselines only;
        WeightedPose takes its branch configs from the trained baselines).
    loss_weights: changes to the weights of the policy's loss preset
        (``wpbench.models.loss_presets``), e.g. {"rotation": 0.05}; config.json records the
        weights actually used.
    """

    policy: str
    data: Path | str | list = Path("data")
    out: Path | None = None
    weights_root: Path | None = None
    minutes: float = 20.0
    steps: int | None = None
    max_steps: int | None = None
    steps_per_epoch: int = 40
    batch_size: int = 8
    learning_rate: float | None = None
    mixing_warmup: float | None = None
    lr_schedule: str = "cosine"
    grad_clip: float = 1.0
    num_action_points: int = 128
    num_anchor_points: int = 512
    augment_yaw: bool = True
    augment_mirror: bool = True  # with augment_yaw: also reflect half the scenes (wpbench.data.augment)
    # Scale each scene by a factor in [1 - s, 1 + s] (wpbench.data.augment.random_scale);
    # None = the policy's default (``specs``), resolved here so config.json records the number.
    augment_scale: float | None = None
    # Stretch drawer samples along their slide by [1 - s, 1 + s] (wpbench.data.augment.random_slide_stretch);
    # None = the policy's default.
    augment_stretch: float | None = None
    # Gate (deg) for retargeting a symmetric object to another equivalent goal; None = the policy's.
    retarget_within_deg: float | None = None
    # Turn every door's training goal this many degrees past its stop (wpbench.training.past_stop);
    # validation keeps the true goals. 0 = the goals as generated.
    door_past_stop_deg: float = 0.0
    # Cap on a turned door goal's whole turn (deg); None = no cap.
    door_max_turn_deg: float | None = None
    val_per_kind: int = 32
    final_val_per_kind: int = 200
    seed: int = 0
    threads: int = 1
    model_overrides: dict = field(default_factory=dict)
    loss_weights: dict = field(default_factory=dict)
    data_sources: tuple = field(default=(), init=False)

    def __post_init__(self) -> None:
        from wpbench.training.data_mix import as_sources

        self.data_sources = as_sources(self.data)
        self.data = self.data_sources[0].path
        self.weights_root = Path(self.weights_root) if self.weights_root is not None else shipped_weights_root()
        self.out = Path(self.out) if self.out is not None else default_run_dir(self.policy)
        if self.minutes <= 0:
            raise ValueError(f"minutes must be > 0, got {self.minutes}")
        for name in ("steps_per_epoch", "batch_size", "num_action_points", "num_anchor_points",
                     "val_per_kind", "final_val_per_kind", "threads"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.lr_schedule not in ("constant", "cosine"):
            raise ValueError(f"lr_schedule must be 'constant' or 'cosine', got {self.lr_schedule!r}")
        from wpbench.training.specs import get_spec

        spec = get_spec(self.policy)
        for name in ("augment_scale", "augment_stretch", "retarget_within_deg"):  # None = the policy's default
            if getattr(self, name) is None:
                setattr(self, name, getattr(spec, name))
        for name in ("augment_scale", "augment_stretch"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {getattr(self, name)}")
        if not 0.0 <= self.retarget_within_deg <= 180.0:
            raise ValueError(f"retarget_within_deg must be in [0, 180] degrees, got {self.retarget_within_deg}")
        if not 0.0 <= self.door_past_stop_deg < 90.0:
            raise ValueError(f"door_past_stop_deg must be in [0, 90) degrees, got {self.door_past_stop_deg}")
        if self.door_max_turn_deg is not None and not 0.0 < self.door_max_turn_deg <= 180.0:
            raise ValueError(f"door_max_turn_deg must be in (0, 180] degrees, got {self.door_max_turn_deg}")
        if self.mixing_warmup is not None and not 0.0 <= self.mixing_warmup < 1.0:
            raise ValueError(f"mixing_warmup must be in [0, 1), got {self.mixing_warmup}")
        self.loss_preset()  # unknown terms or negative weights fail here, before any data is read
        for name in ("steps", "max_steps"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")

    def loss_preset(self):
        """The policy's ``LossPreset`` with ``loss_weights`` applied."""
        from dataclasses import replace

        from wpbench.models.loss_presets import get_preset
        from wpbench.training.specs import get_spec

        preset = get_preset(get_spec(self.policy).loss_preset)
        unknown = sorted(set(self.loss_weights) - set(preset.weights))
        if unknown:
            raise ValueError(f"unknown loss term(s) {unknown}; the terms are {sorted(preset.weights)}")
        return replace(preset, **{name: float(value) for name, value in self.loss_weights.items()})

    def to_json(self) -> dict:
        d = asdict(self)
        for key in ("data", "out", "weights_root"):
            d[key] = str(d[key])
        if self.is_mix():
            d["data_sources"] = [source.text() for source in self.data_sources]
        else:
            d.pop("data_sources")  # one data root: recorded as "data" alone
        return d

    def is_mix(self) -> bool:
        """More than one data set (one set, with or without a weight, trains as a single data root)."""
        return len(self.data_sources) > 1
