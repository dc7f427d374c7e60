"""``wpbench train --policy NAME``: train a learned policy into a run folder (see ``wpbench.training``);
``wpbench train --promote RUN``: ship a finished run as the policy's weights (see ``wpbench.weights``)."""

from __future__ import annotations

from pathlib import Path

import typer

from wpbench.cli.choices import check_choice
from wpbench.names import TRAINABLE_POLICIES as POLICY_NAMES


def train(
    policy: str = typer.Option(None, help=f"Policy to train: {', '.join(POLICY_NAMES)}."),
    data: list[str] = typer.Option(
        None, "--data", metavar="PATH[:WEIGHT]",
        help="Data root with train/ and val/ (from `wpbench data generate`) [default: data]. Repeat to mix data "
             "sets: --data data3:0.7 --data data-own:0.3 draws each training sample from data3/train with "
             "probability 0.7 and from data-own/train with 0.3, whatever their sizes (no :WEIGHT = weight 1; "
             "weights are normalised). Validation and model selection use the first set's val/ only. "
             "config.json records the mix (data.mix)."),
    minutes: float = typer.Option(20.0, min=0.01, help="Training wall-time budget in minutes (summed over resumes)."),
    out: Path = typer.Option(None, help="Run folder to write (and resume from) [default: runs/train/<policy>]."),
    weights_root: Path = typer.Option(None, help="Folder of trained policies: WeightedPose starts from its gf/ and tp/ "
                                                 "(runs/train to start from your own runs); --promote and "
                                                 "--select-best write into it [default: policies/weights]."),
    batch_size: int = typer.Option(8, min=1, help="Samples per optimiser step."),
    steps_per_epoch: int = typer.Option(40, min=1, help="Optimiser steps between validation + checkpoint."),
    steps: int = typer.Option(None, min=1, help="Budget in optimiser steps: schedule and warm-up run over steps, "
                                                "so the result does not depend on the machine's load "
                                                "(--minutes stays a wall-time cap)."),
    max_steps: int = typer.Option(None, min=1, help="Stop after this many optimiser steps (whatever the budget)."),
    learning_rate: float = typer.Option(None, help="Adam learning rate [default: 1e-3 baselines, 1e-4 WeightedPose]."),
    mixing_warmup: float = typer.Option(None, min=0.0, max=0.99,
                                        help="WeightedPose: fraction of the budget training the mixing head alone, "
                                             "branches frozen [default: 0.25]."),
    model_option: list[str] = typer.Option(
        None, "--model-option",
        help="KEY=VALUE change of the model config (baselines; WeightedPose takes its branches' configs). "
             "Dotted keys reach nested configs, values are JSON: --model-option anchor_extent=true "
             "--model-option encoder.k=20."),
    loss_weight: list[str] = typer.Option(
        None, "--loss-weight",
        help="TERM=WEIGHT change of the policy's loss preset (wpbench.models.loss_presets), e.g. "
             "--loss-weight rotation=0.05; 0 drops a term."),
    lr_schedule: str = typer.Option("cosine", help="constant, or cosine (decay to 5% over the budget)."),
    num_action_points: int = typer.Option(128, min=8, help="Action points per cloud in training (random subset)."),
    num_anchor_points: int = typer.Option(512, min=8, help="Anchor points per cloud in training (random subset)."),
    val_per_kind: int = typer.Option(32, min=1, help="Validation samples per kind after each epoch."),
    final_val_per_kind: int = typer.Option(200, min=1, help="Validation samples per kind for metrics.json."),
    threads: int = typer.Option(1, min=1, help="torch threads (1 when two trainings share the machine)."),
    seed: int = typer.Option(0, help="Seed for initialisation, shuffling and augmentation."),
    augment: bool = typer.Option(True, help="Random yaw of each training scene."),
    mirror: bool = typer.Option(True, help="With --augment: also mirror half the scenes (left and right hinges)."),
    scale: float = typer.Option(None, min=0.0, max=0.99,
                                help="Scale each training scene by a random factor in [1 - SCALE, 1 + SCALE] "
                                     "[default: the policy's; 0.15 for gf and the WeightedPose variants, 0 for tp]."),
    stretch: float = typer.Option(None, min=0.0, max=0.99,
                                  help="Stretch each drawer sample along its slide by a random factor in "
                                       "[1 - STRETCH, 1 + STRETCH] [default: the policy's; 0.25 for gf and the WeightedPose "
                                       "variants, 0 for tp]."),
    retarget_within: float = typer.Option(
        None, min=0.0, max=180.0,
        help="Symmetric objects: train towards another equivalent goal once the prediction is within this "
             "many degrees of it; 180 = always the nearest [default: the policy's]."),
    door_past_stop: float = typer.Option(
        0.0, "--door-past-stop", min=0.0, max=89.9, metavar="DEG",
        help="Train every side-hinged door towards its stop turned DEG further about its hinge: the stop is hidden, and a door "
             "driven past it is held there (wpbench.training.past_stop). Validation keeps the true goals."),
    door_max_turn: float = typer.Option(
        None, "--door-max-turn", min=0.1, max=180.0, metavar="DEG",
        help="With --door-past-stop: a turned door goal turns at most DEG in all, so a wide door (a fridge) is not aimed "
             "beyond an arm's reach [default: no cap]."),
    restart: bool = typer.Option(False, help="Ignore an existing checkpoint and start from scratch."),
    select_best: bool = typer.Option(False, "--select-best",
                                     help="Do not train: write WEIGHTS_ROOT/best.json from the trained WeightedPose variants."),
    promote: Path = typer.Option(None, "--promote", metavar="RUN_DIR",
                                 help="Do not train: ship the finished run RUN_DIR as WEIGHTS_ROOT/<its policy>/ "
                                      "(model.pt, config.json, metrics.json, training log). Refused unless its "
                                      "config.json names a trainable policy whose model loads model.pt, its "
                                      "metrics.json has finite validation errors and its progress.json says done; "
                                      "a WeightedPose variant also re-selects best.json."),
) -> None:
    """Train POLICY on DATA into a run folder (OUT, default runs/train/POLICY; resumes from its
    checkpoint.pt): model.pt, config.json, metrics.json, train_log.csv and train_log.png.
    The shipped weights (policies/weights) change only with --promote RUN_DIR."""
    if promote is not None and select_best:
        raise typer.BadParameter("give --promote or --select-best, not both (--promote re-selects best.json itself)",
                                 param_hint="'--promote'")
    if promote is not None:
        _promote(promote, weights_root)
        return
    if select_best:
        from wpbench.weights import select_best as choose
        from wpbench.weights import weights_root_or_shipped

        weights_root = weights_root_or_shipped(weights_root)
        try:
            best = choose(weights_root)
        except ValueError as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(2)
        if best is None:
            typer.echo(f"Error: no trained WeightedPose variant under {weights_root}; "
                       "train one with `wpbench train --policy wp-postsvd-t` and ship it with `--promote`", err=True)
            raise typer.Exit(2)
        typer.echo(f"best: {best['policy']} ({best['criterion']}: {best['candidates']}) -> {weights_root}/best.json")
        return
    if policy is None:
        raise typer.BadParameter(f"give --policy, one of: {', '.join(POLICY_NAMES)}", param_hint="'--policy'")
    check_choice("policy", policy, POLICY_NAMES)
    from wpbench.training.config import TrainConfig
    from wpbench.training.loop import train as run_training

    try:
        overrides = parse_model_options(model_option or [])
        loss_weights = parse_loss_weights(loss_weight or [])
        config = TrainConfig(
            policy=policy, data=list(data) if data else [Path("data")], out=out, weights_root=weights_root, minutes=minutes, steps=steps, max_steps=max_steps,
            steps_per_epoch=steps_per_epoch, batch_size=batch_size, learning_rate=learning_rate, mixing_warmup=mixing_warmup,
            lr_schedule=lr_schedule,
            num_action_points=num_action_points, num_anchor_points=num_anchor_points, augment_yaw=augment, augment_mirror=mirror, augment_scale=scale,
            augment_stretch=stretch, retarget_within_deg=retarget_within,
            door_past_stop_deg=door_past_stop, door_max_turn_deg=door_max_turn,
            val_per_kind=val_per_kind, final_val_per_kind=final_val_per_kind, seed=seed, threads=threads,
            model_overrides=overrides, loss_weights=loss_weights,
        )
        metrics = run_training(config, echo=typer.echo, restart=restart)
    except (ValueError, FileNotFoundError) as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    for kind, values in metrics["val"].items():
        typer.echo(f"  val {kind}: rotation {values['rot_deg']:.2f} deg, translation {values['trans_m'] * 100:.2f} cm, "
                   f"point {values['point_m'] * 100:.2f} cm (n={values['n']})")
    typer.echo(f"weights: {config.out}/model.pt ({metrics['train_wall_s'] / 60:.1f} min, "
               f"peak RSS {metrics['peak_rss_mib']:.0f} MiB); ship them with `wpbench train --promote {config.out}`")


def _promote(run_dir: Path, weights_root: Path | None) -> None:
    from wpbench.weights import promote

    try:
        shipped = promote(run_dir, weights_root)
    except ValueError as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    typer.echo(f"promoted {shipped['policy']} (model_hash {shipped['model_hash']}): {run_dir} -> {shipped['weights_dir']}")
    typer.echo(f"  {_data_line(Path(shipped['weights_dir']))}")
    best = shipped["best"]
    if shipped["best_unchanged"]:
        typer.echo(f"Warning: best.json left as it was: {shipped['best_unchanged']}", err=True)
    if best is not None:
        typer.echo(f"best WeightedPose variant: {best['policy']} ({best['criterion']}: {best['candidates']})")


def _data_line(weights_dir: Path) -> str:
    """What the weights in ``weights_dir`` were trained on, from their config.json."""
    import json

    from wpbench.training.data_mix import describe_data
    from wpbench.weights import CONFIG_FILE

    return describe_data(json.loads((weights_dir / CONFIG_FILE).read_text()).get("data", {}))


def parse_model_options(options: list[str]) -> dict:
    """["encoder.k=20", "anchor_extent=true"] -> {"encoder": {"k": 20}, "anchor_extent": True}."""
    import json

    overrides: dict = {}
    for option in options:
        key, sep, text = option.partition("=")
        if not sep or not key:
            raise ValueError(f"--model-option {option!r} is not KEY=VALUE (for example anchor_extent=true)")
        try:
            value = json.loads(text)
        except json.JSONDecodeError as err:
            raise ValueError(f"--model-option {option!r}: the value must be JSON (true, 20, [32, 64], \"x\"): {err}") from err
        *parents, leaf = key.split(".")
        node = overrides
        for parent in parents:
            node = node.setdefault(parent, {})
        node[leaf] = value
    return overrides


def parse_loss_weights(options: list[str]) -> dict[str, float]:
    """["rotation=0.05", "translation=2"] -> {"rotation": 0.05, "translation": 2.0}."""
    weights: dict[str, float] = {}
    for option in options:
        name, _, text = option.partition("=")
        try:
            weight = float(text)  # "rotation" alone leaves text empty, which fails here too
        except ValueError:
            weight = None
        if not name or weight is None:
            raise ValueError(f"--loss-weight {option!r} is not TERM=NUMBER (for example rotation=0.05)")
        weights[name] = weight
    return weights


_single = typer.Typer(add_completion=False)
_single.command(name="train")(train)
# A click command (not a group), so the call is `wpbench train --policy gf`.
app = typer.main.get_command(_single)
