"""``wpbench data generate``: sample training data from the tasks (see ``wpbench.data``)."""

from __future__ import annotations

from pathlib import Path

import typer

from wpbench import names
from wpbench.cli.camera_noise_options import (
    camera_noise_settings,
    depth_holes_option,
    depth_noise_option,
    edge_holes_option,
    seg_noise_option,
)
from wpbench.cli.choices import check_choice

app = typer.Typer(help="Generate training data from the simulator.", add_completion=False, no_args_is_help=True)


@app.command()
def generate(
    out: Path = typer.Option(Path("data"), help="Root folder; samples go to OUT/<split>/."),
    samples_per_kind: int = typer.Option(1500, min=1, help="Samples of each kind (rounded up to whole shards)."),
    split: str = typer.Option("train", help=f"Furniture split: {', '.join(names.SPLITS)} (disjoint instances)."),
    obs: str = typer.Option("camera", help="Observation: camera (depth + segmentation) or mesh (surface samples)."),
    depth_noise: float = depth_noise_option(),
    depth_holes: float = depth_holes_option(),
    edge_holes: bool = edge_holes_option(),
    seg_noise_px: int = seg_noise_option(),
    seed: int = typer.Option(0, help="Base seed; every sample's episode seed is derived from it."),
    kind: list[str] = typer.Option(None, help=f"Only this kind (repeatable): {', '.join(names.KINDS)} [default: all]."),
    shard_size: int = typer.Option(50, min=1, help="Samples per shard file (lowered to fit small runs)."),
    scene_reuse: int = typer.Option(5, min=1, help="Consecutive samples sharing one loaded furniture instance."),
    wide_start_probability: float = typer.Option(
        None, help="Chance an articulated start is drawn in 0-90% open [default: 0.5 for train, 0 for val]."),
    num_action_points: int = typer.Option(256, min=8, help="Action-object points per sample."),
    num_anchor_points: int = typer.Option(1024, min=8, help="Anchor-object points per sample."),
    extra_train_instances: int = typer.Option(
        0, min=0, help="Train split only: this many more procedural furniture instances per category "
        "(the val instances are unchanged and never trained on)."),
    assets: str = typer.Option("procedural", help="'procedural' (built-in furniture) or a folder of your own "
                               "PartNet-Mobility objects split with `wpbench assets split`."),
    progress: bool = typer.Option(True, help="Show a progress bar."),
    workers: int = typer.Option(None, min=1, help="Processes drawing whole shards side by side [default: 1]; the "
                                                  "shards are the same whatever the number."),
    ray: str = typer.Option(
        None, "--ray", metavar="ADDRESS",
        help="Draw whole shards as tasks on a Ray cluster, one CPU each: 'local' (or --ray alone) starts one "
             "on this machine, 'auto' joins the one this machine belongs to, HOST:PORT another one. This process writes the "
             "shards; the nodes need no shared file system."),
) -> None:
    """Sample (action cloud, anchor cloud, cross-pose) triples into OUT/<split>/ shards + manifest.json.

    Resumable: shards already on disk are skipped; rerun the same command after an interruption.
    """
    from wpbench.cli.run_cmd import ray_address
    from wpbench.data.config import GenerationConfig
    from wpbench.data.generate import generate as run_generation
    from wpbench.evaluation.local_workers import WorkerError

    if workers is not None and ray is not None:
        typer.echo("Error: --workers and --ray cannot be combined: shards are drawn either by local processes "
                   "or by the Ray cluster's CPUs", err=True)
        raise typer.Exit(2)
    check_choice("split", split, names.SPLITS)
    check_choice("observation mode", obs, names.OBS_MODES)
    camera_noise = camera_noise_settings(obs, depth_noise, depth_holes, edge_holes, seg_noise_px)
    kinds = tuple(kind) if kind else names.KINDS
    for k in kinds:
        check_choice("kind", k, names.KINDS)
    scene_reuse = min(scene_reuse, samples_per_kind)
    if samples_per_kind < shard_size:
        shard_size = samples_per_kind
    shard_size = max(scene_reuse, shard_size - shard_size % scene_reuse)
    if wide_start_probability is None:
        wide_start_probability = 0.5 if split == "train" else 0.0
    if extra_train_instances and (split != "train" or assets != "procedural"):
        typer.echo("Error: --extra-train-instances adds procedural training furniture; use it with --split train "
                   "and --assets procedural", err=True)
        raise typer.Exit(2)
    try:
        config = GenerationConfig(
            split=split, obs=obs, seed=seed, samples_per_kind=samples_per_kind, kinds=kinds,
            shard_size=shard_size, scene_reuse=scene_reuse, wide_start_probability=wide_start_probability,
            num_action_points=num_action_points, num_anchor_points=num_anchor_points,
            extra_train_instances=extra_train_instances, assets=assets, camera_noise=camera_noise,
        )
        report = run_generation(out, config, progress=progress, workers=workers or 1, use_ray=ray is not None,
                                ray_address=ray_address(ray))
    except (ValueError, FileNotFoundError, WorkerError) as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(2)
    m = report.manifest
    typer.echo(
        f"{report.directory}: wrote {report.written_shards} shard(s), skipped {report.skipped_shards}; "
        f"{report.new_samples} new samples in {report.seconds:.1f} s ({report.samples_per_second:.2f} samples/s)"
    )
    for k, n in m["counts"].items():
        cats = ", ".join(f"{c} {v}" for c, v in m["counts_by_category"][k].items())
        typer.echo(f"  {k}: {n} ({cats})")
    typer.echo(f"manifest: {report.directory / 'manifest.json'} (content hash {m['content_hash']})")
