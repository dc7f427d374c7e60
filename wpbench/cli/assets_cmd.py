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
