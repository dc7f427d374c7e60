"""The trainer: ``train(TrainConfig) -> metrics``.

Read top to bottom: load data (one data root, or several mixed by weight:
``wpbench.training.data_mix``) -> build (or warm-start) the model -> resume from
``checkpoint.pt`` if there is one -> epochs of ``steps_per_epoch`` optimiser
steps, each followed by validation, a log row, a checkpoint and the plot ->
stop at the time budget (or ``max_steps``) -> final validation -> ``model.pt``,
``config.json``, ``metrics.json`` (``wpbench.weights.save_trained``) in the run folder.
Shipping a run is a separate step (``wpbench.weights.promote``).
"""

from __future__ import annotations

import math
import resource
import time
from collections.abc import Callable
from pathlib import Path

import torch

from wpbench.data.config import KINDS
from wpbench.data.dataset import CrossPoseDataset
from wpbench.models.loss_presets import compute_loss
from wpbench.training import log as train_log
from wpbench.training.batches import make_batch, prepare
from wpbench.training.checkpoint import load_checkpoint, save_checkpoint
from wpbench.training.past_stop import turn_doors_past_stop
from wpbench.training.config import TrainConfig
from wpbench.training.data_mix import load_mix, mix_hash, mix_record, training_batches
from wpbench.training.evaluate import evaluate, mean_point_error
from wpbench.training.specs import PolicySpec, get_spec
from wpbench.training.warmup import in_warmup, set_phase
from wpbench.weights import config_to_json, load_trained_model, save_trained

# The PNG of the training log is redrawn this often (and at the end), since a plot costs far more
# than an epoch's CSV row, which is written every epoch.
PLOT_EVERY_EPOCHS = 10


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def build_policy_model(spec: PolicySpec, config: TrainConfig) -> tuple[torch.nn.Module, dict]:
    """The model to train and a description of where it started.

    WeightedPose variants start from the trained Goal Flow and TAX-Pose weights
    (their configs fix the branch sizes and the point counts).
    """
    from wpbench.models.registry import build_model

    if not spec.starts_from:
        return build_model(spec.model, **config.model_overrides), {"from": "scratch"}
    if config.model_overrides:
        raise ValueError(
            f"{spec.name} takes its branch configs from the trained {' and '.join(spec.starts_from)}; "
            f"model options {config.model_overrides} belong to their training (wpbench train --policy gf --model-option ...)"
        )
    from wpbench.models.configs import WeightedPoseConfig
    from wpbench.models.weightedpose import WeightedPose

    loaded = {}
    for name in spec.starts_from:
        try:
            loaded[name] = load_trained_model(config.weights_root / name, name)
        except FileNotFoundError as err:
            commands = " && ".join(f"wpbench train --policy {n}" for n in spec.starts_from)
            raise FileNotFoundError(
                f"{spec.name} starts from the trained {' and '.join(spec.starts_from)} weights: {err}. "
                f"Train them first: `{commands}`"
            ) from err
    (gf_model, gf_cfg), (tp_model, tp_cfg) = loaded["gf"], loaded["tp"]
    wp_config = WeightedPoseConfig(goalflow=gf_model.config, taxpose=tp_model.config,
                                   w_mode=gf_model.config.mixing_weight)
    model = WeightedPose.from_pretrained(gf_model.state_dict(), tp_model.state_dict(), wp_config)
    for name, (_, cfg) in loaded.items():
        counts = (cfg["num_action_points"], cfg["num_anchor_points"])
        if counts != (config.num_action_points, config.num_anchor_points):
            raise ValueError(
                f"{name} was trained on {counts[0]} action / {counts[1]} anchor points but this run uses "
                f"{config.num_action_points} / {config.num_anchor_points}; use the same point counts"
            )
    origin = {"from": {name: {"model_hash": cfg.get("model_hash", ""), "data": cfg.get("data", {})}
                       for name, (_, cfg) in loaded.items()}}
    return model, origin


def _load_data(config: TrainConfig, spec: PolicySpec):
    """(train samples, val set, data hashes, per-set descriptions or None for one data root).

    A mix trains on every set's train/ and validates on the first set's val/."""
    if config.is_mix():
        train_set, described = load_mix(config.data_sources, spec.kinds)
        val_set = CrossPoseDataset(config.data / "val", spec.kinds)
        return train_set, val_set, {"train": mix_hash(described), "val": val_set.content_hash}, described
    train_set = CrossPoseDataset(config.data / "train", spec.kinds)
    val_set = CrossPoseDataset(config.data / "val", spec.kinds)
    return train_set, val_set, {"train": train_set.content_hash, "val": val_set.content_hash}, None


def scheduled_lr(base: float, schedule: str, elapsed: float, budget: float) -> float:
    """Learning rate after ``elapsed`` of ``budget`` seconds ("cosine": base -> 5% of base)."""
    if schedule == "constant":
        return base
    progress = min(max(elapsed / budget, 0.0), 1.0)
    return base * (0.05 + 0.95 * 0.5 * (1.0 + math.cos(math.pi * progress)))


def phase_lr(spec: PolicySpec, base: float, schedule: str, elapsed: float, budget: float, warmup: float) -> float:
    """The learning rate at ``elapsed``: the mixing head's own during the warm-up, then
    ``base`` on its schedule over what is left of the budget."""
    if in_warmup(elapsed, budget, warmup):
        return spec.mixing_learning_rate
    start = warmup * budget
    return scheduled_lr(base, schedule, elapsed - start, budget - start)


def _val_row(results: dict[str, dict[str, float]]) -> dict[str, float]:
    row: dict[str, float] = {}
    for kind, values in results.items():
        short = "art" if kind == KINDS[0] else "free"
        for key in ("rot_deg", "trans_m", "point_m"):
            row[f"val_{short}_{key}"] = values[key]
        if "w" in values:
            row[f"val_{short}_w"] = values["w"]
    row["val_mean_point_m"] = mean_point_error(results)
    return row


def _door_goals_text(past_stop_deg: float, max_turn_deg: float | None) -> str:
    cap = "" if max_turn_deg is None else f" (at most {max_turn_deg:g} deg in all)"
    return f"{past_stop_deg:g} deg past the stop{cap}"


def train(config: TrainConfig, echo: Callable[[str], None] = print, restart: bool = False) -> dict:
    """Train ``config.policy``; resumes from ``config.out/checkpoint.pt`` unless ``restart``."""
    spec = get_spec(config.policy)
    preset = config.loss_preset()
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    train_set, val_set, data_hashes, mix = _load_data(config, spec)
    if config.door_past_stop_deg > 0:
        train_set.gt_transform, train_set.gt_equivalents, turned = turn_doors_past_stop(
            train_set.gt_transform, train_set.gt_equivalents, train_set.kind, config.door_past_stop_deg,
            config.door_max_turn_deg)
        echo(f"door goals turned {_door_goals_text(config.door_past_stop_deg, config.door_max_turn_deg)} in {turned} "
             f"training samples; validation keeps the true goals")
    model, origin = build_policy_model(spec, config)
    lr = config.learning_rate if config.learning_rate is not None else spec.learning_rate
    warmup = config.mixing_warmup if config.mixing_warmup is not None else spec.mixing_warmup
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    generator = torch.Generator().manual_seed(config.seed)

    epoch, step, elapsed, rows = 0, 0, 0.0, []
    drawn = [0] * len(config.data_sources)  # training samples drawn from each data set
    state = None if restart else load_checkpoint(out)
    if state is not None:
        if state["policy"] != config.policy or state["data"] != data_hashes:
            raise ValueError(
                f"{out}/checkpoint.pt belongs to policy {state['policy']!r} on data {state['data']}, not "
                f"{config.policy!r} on {data_hashes}; pass --restart to start over or choose another --out"
            )
        past_stop = (state.get("door_past_stop_deg", 0.0), state.get("door_max_turn_deg"))
        if past_stop != (config.door_past_stop_deg, config.door_max_turn_deg):
            raise ValueError(
                f"{out}/checkpoint.pt was trained with door goals {_door_goals_text(*past_stop)}, not "
                f"{_door_goals_text(config.door_past_stop_deg, config.door_max_turn_deg)}; pass --restart to start over "
                f"or choose another --out"
            )
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        generator.set_state(state["generator"])
        epoch, step, elapsed, rows = state["epoch"], state["step"], state["elapsed_s"], state["rows"]
        drawn = list(state.get("drawn_by_data", drawn))
        echo(f"resuming {config.policy} from epoch {epoch}, step {step}, {elapsed / 60:.1f} min trained")
    budget = config.minutes * 60.0
    batches = training_batches(train_set, config.data_sources, config.batch_size, generator)
    budget_text = f"{config.steps} steps (at most {config.minutes} min)" if config.steps else f"{config.minutes} min"
    echo(f"{config.policy}: {len(train_set)} train / {len(val_set)} val samples ({', '.join(spec.kinds)}), "
         f"{sum(p.numel() for p in model.parameters())} parameters, lr {lr}, budget {budget_text}"
         + (f", the first {warmup:.0%} training the mixing head alone" if warmup > 0 else ""))
    if mix is not None:
        echo("data mix: " + "; ".join(f"{d['path']} {d['weight']:.0%} of samples ({d['samples']} samples)" for d in mix)
             + f"; validation on {config.data}/val")

    # The budget is wall time: validation, checkpoints and the log count too, so that "trained for N
    # minutes" is what a user waits.
    clock_started, trained_before = time.perf_counter(), elapsed

    def trained() -> float:
        return trained_before + time.perf_counter() - clock_started

    # With a step budget the schedule and the warm-up follow steps, not seconds: a run then gives
    # the same weights whether it had the machine alone or shared it.
    step_caps = [cap for cap in (config.steps, config.max_steps) if cap is not None]
    step_cap = min(step_caps) if step_caps else None

    def position() -> tuple[float, float]:
        """How far the run is through its budget, as (done, total) in steps or seconds."""
        if config.steps is not None:
            return float(step), float(config.steps)
        return trained(), budget

    def out_of_steps() -> bool:
        return step_cap is not None and step >= step_cap

    def finished() -> bool:
        return out_of_steps() or trained() >= budget

    last_epoch_seconds = 0.0
    model.train()
    while not finished():
        # Do not start an epoch that would overrun the budget by more than half an epoch.
        if rows and trained() + 0.5 * last_epoch_seconds > budget:
            break
        epoch_started = trained()
        # The phase is chosen per epoch from the budget position (time or steps), so a resumed run picks it up.
        mixing_only = in_warmup(*position(), warmup)
        if warmup > 0:
            set_phase(model, mixing_only)
        sums: dict[str, float] = {}
        steps_done = skipped = 0
        while steps_done < config.steps_per_epoch and not out_of_steps():
            for group in optimizer.param_groups:
                group["lr"] = phase_lr(spec, lr, config.lr_schedule, *position(), warmup)
            indices, sets = next(batches)
            for which in sets.tolist():
                drawn[which] += 1
            batch = prepare(make_batch(train_set, indices), config.num_action_points,
                            config.num_anchor_points, config.augment_yaw, generator,
                            config.augment_mirror, config.augment_scale, config.augment_stretch)
            output = model(batch["action"], batch["anchor"])
            loss, terms = compute_loss(output, batch, preset, config.retarget_within_deg)
            optimizer.zero_grad(set_to_none=True)
            if not torch.isfinite(loss):
                skipped += 1  # a degenerate SVD in one batch must not poison the weights
            else:
                loss.backward()
                torch.nn.utils.clip_grad_norm_(model.parameters(), config.grad_clip)
                optimizer.step()
                sums["train_loss"] = sums.get("train_loss", 0.0) + float(loss.detach())
                for name, value in terms.items():
                    sums[f"loss_{name}"] = sums.get(f"loss_{name}", 0.0) + float(value)
            steps_done += 1
            step += 1
            if trained() >= budget:
                break
        results = evaluate(model, val_set, spec.kinds, config.val_per_kind, config.num_action_points,
                           config.num_anchor_points, seed=config.seed)
        elapsed = trained()
        last_epoch_seconds = elapsed - epoch_started
        epoch += 1
        good = max(steps_done - skipped, 1)
        row = {"epoch": epoch, "step": step, "elapsed_s": round(elapsed, 1), "skipped_steps": skipped,
               "lr": optimizer.param_groups[0]["lr"], "mixing_only": int(mixing_only),
               **{k: v / good for k, v in sums.items()}, **_val_row(results)}
        rows.append(row)
        save_checkpoint(out, {"policy": config.policy, "data": data_hashes, "door_past_stop_deg": config.door_past_stop_deg,
                              "door_max_turn_deg": config.door_max_turn_deg,
                              "model": model.state_dict(),
                              "optimizer": optimizer.state_dict(), "generator": generator.get_state(),
                              "epoch": epoch, "step": step, "elapsed_s": elapsed, "rows": rows, "drawn_by_data": drawn,
                              "train_config": config.to_json()})
        train_log.write_log(out, rows)
        if epoch % PLOT_EVERY_EPOCHS == 0:
            train_log.plot_log(out, rows, f"{config.policy} ({spec.loss_preset} loss)")
        train_log.write_progress(out, {"policy": config.policy, "status": "training", "epoch": epoch, "step": step,
                                       "elapsed_min": round(elapsed / 60, 2), "budget_min": config.minutes,
                                       "last_row": row})
        echo(f"epoch {epoch} step {step} {elapsed / 60:.1f} min loss {row.get('train_loss', math.nan):.4g} "
             f"val point {row['val_mean_point_m'] * 100:.2f} cm "
             + " ".join(f"{k} {v['rot_deg']:.1f}deg/{v['trans_m'] * 100:.1f}cm" for k, v in results.items()))

    elapsed = trained()
    if config.steps is not None and step < config.steps:
        echo(f"warning: the {config.minutes} min cap stopped the run at step {step} of its {config.steps}-step "
             f"budget, so its schedule did not finish; raise --minutes and run again to resume")
    if rows:
        train_log.plot_log(out, rows, f"{config.policy} ({spec.loss_preset} loss)")
    final_started = time.perf_counter()
    final = evaluate(model, val_set, spec.kinds, config.final_val_per_kind, config.num_action_points,
                     config.num_anchor_points, seed=config.seed + 1)
    metrics = {
        "policy": config.policy,
        "val": final,
        "val_mean_point_m": mean_point_error(final),
        "train_wall_s": round(elapsed, 1),
        "final_eval_s": round(time.perf_counter() - final_started, 1),
        "steps": step,
        "epochs": epoch,
        "samples_seen": step * config.batch_size,
        **({"samples_drawn_by_data": {d["path"]: n for d, n in zip(mix, drawn)}} if mix is not None else {}),
        "peak_rss_mib": round(peak_rss_mib(), 1),
    }
    description = {
        "policy": config.policy,
        "model": spec.model,
        "model_config": config_to_json(model.config),
        "loss_preset": spec.loss_preset,
        "loss_weights": preset.weights,
        "kinds": list(spec.kinds),
        "num_action_points": config.num_action_points,
        "num_anchor_points": config.num_anchor_points,
        "data": {"path": str(config.data), **{f"{k}_manifest_hash": v for k, v in data_hashes.items()},
                 **({"val_from": str(config.data), "mix": mix_record(mix, drawn)} if mix is not None else {})},
        "init": origin,
        "train_config": config.to_json(),
    }
    save_trained(out, model, description, metrics)
    train_log.write_progress(out, {"policy": config.policy, "status": "done", "epoch": epoch, "step": step,
                                   "elapsed_min": round(elapsed / 60, 2), "budget_min": config.minutes,
                                   "metrics": metrics})
    return metrics
