"""``wpbench assets``: generate, list and look at the furniture library."""

from __future__ import annotations

from pathlib import Path

import typer

from wpbench.names import SPLITS

app = typer.Typer(help="Generate, list and render furniture assets.", add_completion=False, no_args_is_help=True)


def _fail(message: str) -> None:
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code=2)


@app.command()
def generate(
    out: Path = typer.Option(None, help="Output folder [default: the cache used by --assets procedural]."),
    per_category: int = typer.Option(16, min=1, help="Objects per category."),
    val_per_category: int = typer.Option(None, min=0, help="Validation objects per category [default: a quarter]."),
    seed: int = typer.Option(0, help="Library seed; the same seed writes byte-identical files."),
    category: list[str] = typer.Option(None, help="Only this category (repeatable) [default: all]."),
    test_per_category: int = typer.Option(None, min=0, help="Held-out test objects per category [default: as in the built-in library]."),
) -> None:
    """Write procedural furniture (PartNet-Mobility layout) and split.json into OUT."""
    from tqdm import tqdm

    from wpbench.assets.library import default_val_per_category, procedural_library
    from wpbench.assets.procedural import CATEGORIES, TEST_PER_CATEGORY, generate_library

    for c in category or ():
        if c not in CATEGORIES:
            _fail(f"unknown category {c!r}; valid: {', '.join(CATEGORIES)}")
    if out is None:
        if category or val_per_category is not None or test_per_category is not None:
            _fail("--category, --val-per-category and --test-per-category need --out "
                  "(the cache always holds the full default library)")
        folder = procedural_library(seed=seed, per_category=per_category)
        typer.echo(f"procedural library (seed {seed}, {per_category} per category): {folder}")
        return
    val = default_val_per_category(per_category) if val_per_category is None else val_per_category
    if val >= per_category:
        _fail(f"--val-per-category ({val}) must be smaller than --per-category ({per_category})")
    tests = TEST_PER_CATEGORY if test_per_category is None else test_per_category
    assets = generate_library(
        out, per_category=per_category, val_per_category=val, seed=seed, categories=category or None,
        progress=lambda jobs: tqdm(jobs, desc="furniture", unit="obj"), test_per_category=tests,
    )
    counts = ", ".join(f"{sum(a.split == s for a in assets)} {s}" for s in SPLITS)
    typer.echo(f"wrote {len(assets)} objects ({counts}) to {out}")


def _find(asset_id: str, assets: str, seed: int, per_category: int):
    from wpbench.assets.library import load_library

    try:
        library = load_library(assets, seed=seed, per_category=per_category)
    except ValueError as err:
        _fail(str(err))
    for a in library:
        if a.object_id == asset_id:
            return a
    ids = [a.object_id for a in library]
    _fail(f"no asset {asset_id!r} in {assets}; there are {len(ids)}, e.g. {', '.join(ids[:6])}")


@app.command()
def show(
    asset_id: str = typer.Argument(..., help="Object id, e.g. oven-0003."),
    out: Path = typer.Option(..., help="PNG to write."),
    assets: str = typer.Option("procedural", help="'procedural' or a folder of assets."),
    seed: int = typer.Option(0, help="Seed of the procedural library."),
    per_category: int = typer.Option(16, min=1, help="Size of the procedural library."),
    width: int = typer.Option(480, min=64, help="Width of each view in pixels."),
) -> None:
    """Render ASSET_ID closed and open side by side (needs SAPIEN's Vulkan renderer)."""
    from wpbench.assets.render import RenderConfig, render_closed_open

    asset = _find(asset_id, assets, seed, per_category)
    path = render_closed_open(asset, out, RenderConfig(width=width, height=width))
    typer.echo(f"wrote {path}")


@app.command("list")
def list_assets(
    assets: str = typer.Option("procedural", help="'procedural' or a folder of assets."),
    split: str = typer.Option(None, help="train, val or test [default: all]."),
    category: list[str] = typer.Option(None, help="Only this category (repeatable)."),
    seed: int = typer.Option(0, help="Seed of the procedural library."),
    per_category: int = typer.Option(16, min=1, help="Size of the procedural library."),
) -> None:
    """One line per asset: id, category, split, target joint, open value, in-region size."""
    from wpbench.assets.library import load_library

    try:
        library = load_library(assets, split=split, categories=category or None, seed=seed, per_category=per_category)
    except ValueError as err:
        _fail(str(err))
    typer.echo(f"{'id':<18}{'category':<12}{'split':<7}{'joint':<10}{'type':<11}{'open':>8}  in-region (m)")
    for a in library:
        size = "x".join(f"{2 * h:.2f}" for h in a.in_region.half_extents)
        typer.echo(f"{a.object_id:<18}{a.category:<12}{str(a.split):<7}{a.target_joint:<10}{a.joint_type:<11}{a.open_qpos:>8.3f}  {size}")
    typer.echo(f"{len(library)} assets")


def _workers_option(value: int | None) -> int | None:
    if value is not None and value < 1:
        raise typer.BadParameter("--workers must be at least 1")
    return value


@app.command()
def prepare(
    folder: Path = typer.Argument(..., help="A folder of PartNet-Mobility objects (or one object folder)."),
    workers: int = typer.Option(None, callback=_workers_option, help="Decomposition processes at once [default: one per core]."),
) -> None:
    """Decompose every object's links into the collision cache the loader reads."""
    from wpbench.assets.partnet import PartNetLoadError
    from wpbench.assets.prepare import prepare_folder

    try:
        results = prepare_folder(folder, workers=workers)
    except PartNetLoadError as err:
        _fail(str(err))
    for r in results:
        if r.error:
            typer.echo(f"{r.folder.name:<12} refused  {r.error}")
        else:
            notes = "; ".join(f"{link}: {why}" for link, why in r.derived.fallbacks.items())
            typer.echo(f"{r.folder.name:<12} ready    decomposition {r.seconds:6.1f} s" + (f"  fallbacks: {notes}" if notes else ""))
    ready = sum(r.error is None for r in results)
    typer.echo(f"{ready} of {len(results)} objects prepared")


@app.command()
def check(
    folder: Path = typer.Argument(..., help="A folder of PartNet-Mobility objects (or one object folder)."),
    workers: int = typer.Option(None, callback=_workers_option, help="Decomposition processes at once [default: one per core]."),
) -> None:
    """One line per object: usable (with its target and decomposition time) or why not."""
    import time

    from wpbench.assets.partnet import PartNetLoadConfig, PartNetLoadError, load_partnet_object
    from wpbench.assets.prepare import prepare_folder

    try:
        results = prepare_folder(folder, workers=workers)
    except PartNetLoadError as err:
        _fail(str(err))
    usable = 0
    for r in results:
        line = f"{r.folder.name:<12} "
        if r.error is None:
            start = time.perf_counter()
            try:
                asset = load_partnet_object(r.folder, config=PartNetLoadConfig(workers=workers))
            except Exception as err:  # one object's failure is its line, not the command's end
                r.error = " ".join(str(err).split()) if isinstance(err, PartNetLoadError) else (
                    f"{r.folder.name}: unexpected {type(err).__name__}: {' '.join(str(err).split())}")
            else:
                usable += 1
                reach = (asset.open_qpos - asset.closed_qpos) / (asset.extra["open_qpos_limit"] - asset.closed_qpos)
                notes = "; ".join(f"{link}: {why}" for link, why in asset.extra["collision_fallbacks"].items())
                line += (f"usable   decomposition {r.seconds:6.1f} s  load {time.perf_counter() - start:5.1f} s  "
                         f"{asset.category} {asset.joint_type} {asset.target_link} opens {reach:.0%} of its range"
                         + (f"  fallbacks: {notes}" if notes else "")
                         + (f"  cleared: trimmed {asset.extra['collision_trimmed']} dropped {asset.extra['collision_dropped']}"
                            if asset.extra["collision_trimmed"] or asset.extra["collision_dropped"] else "")
                         + (f"  no collision for {sorted(asset.extra['collision_restless'])}: they moved while held at rest"
                            if asset.extra.get("collision_restless") else "")
                         + (f"  stops short, {asset.extra['reach_blocked_by']}" if asset.extra["reach_blocked_by"] else ""))
        if r.error is not None:
            line += f"refused  decomposition {r.seconds:6.1f} s  {r.error}"
        typer.echo(line)
    typer.echo(f"{usable} of {len(results)} objects usable")


@app.command()
def split(
    folder: Path = typer.Argument(..., help="A folder of PartNet-Mobility objects."),
    val_fraction: float = typer.Option(0.2, min=0.0, max=0.95, help="Share of each category's objects for val."),
    test_fraction: float = typer.Option(0.2, min=0.0, max=0.95, help="Share of each category's objects for test (held out)."),
    seed: int = typer.Option(0, help="Seed of the shuffle within each category."),
) -> None:
    """Split FOLDER's objects into train / val / test, whole objects, stratified by category.

    Writes FOLDER/wpbench-splits.json, or $WPBENCH_CACHE/splits/ when FOLDER is read-only;
    `wpbench run/data generate --assets FOLDER --split S` then use it.
    """
    from wpbench.assets.object_split import write_split_file

    try:
        path, data, skipped = write_split_file(folder, val_fraction, test_fraction, seed)
    except ValueError as err:
        _fail(str(err))
    for name, reason in sorted(skipped.items()):
        typer.echo(f"left out {reason}")
    for s in SPLITS:
        ids = data["splits"][s]
        by_cat = ", ".join(f"{c} {sum(data['categories'][i] == c for i in ids)}"
                           for c in sorted({data['categories'][i] for i in ids}))
        typer.echo(f"{s:<6}{len(ids):>4} objects  {by_cat}")
    typer.echo(f"wrote {path}")
