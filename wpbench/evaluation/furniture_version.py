"""Whether a run on the built-in furniture was scored on the furniture of today's generator.

A run's ``run.json`` records ``furniture_generator``: the procedural generator's version when
its episodes were made (``None`` for a PartNet-Mobility folder, whose content digest plays
that part). When the generator changes, the same split holds other furniture, so an old run's
success rate no longer describes the current split. The leaderboard leaves such runs out and
the paper table refuses them, both with the reason below; the cure is to move the run under
``results/archive/`` or to score it again.
"""

from __future__ import annotations

from pathlib import Path

from wpbench.evaluation.records import stored_run_config


class OtherFurnitureError(ValueError):
    """A run that a report needs was scored on other built-in furniture than today's."""


def other_furniture_reason(run_dir: str | Path) -> str | None:
    """One line saying why the run in ``run_dir`` is on other built-in furniture than today's,
    or None when it is current, on real objects, or has no readable ``run.json`` (runs made
    before ``run.json`` recorded the generator are taken as they are)."""
    from wpbench.assets.procedural.generate import GENERATOR_VERSION

    stored = stored_run_config(run_dir)
    if stored is None or stored.get("assets") != "procedural":
        return None
    version = stored.get("furniture_generator")
    if version is None or version == GENERATOR_VERSION:
        return None
    return (f"{Path(run_dir)} was scored on built-in furniture of generator version {version}, "
            f"and the current furniture is version {GENERATOR_VERSION}; move it under "
            f"results/archive/ or score it again")
