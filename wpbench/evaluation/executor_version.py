"""Whether a run's episodes were carried out by today's version of its executor.

An executor's path decides an episode as much as the policy does: when the side entry of the
``gripper`` changes, a run made before no longer says what the gripper does today. Each such
change is listed in ``EXECUTOR_CHANGES`` with the executor it changed and the kind of stage it
touches (a change to how a free object is put into a cavity leaves a door's stage as it was).
The version of an (executor, task) pair is one more than the number of listed changes that
touch one of the task's stages; ``run.json`` records it as ``executor_version``, a run.json
without it was made at version 1. ``--resume`` refuses to add episodes of another version to a
run, the leaderboard leaves older runs out and the paper table refuses them, each with the
reason below; the cure is to score the run again.
"""

from __future__ import annotations

from pathlib import Path

from wpbench.evaluation.records import stored_run_config
from wpbench.names import ARTICULATED, FREE, TASKS

# (executor, kind of stage it touches, what changed), oldest first. Append; never edit or remove.
EXECUTOR_CHANGES: tuple[tuple[str, str, str], ...] = (
    ("gripper", FREE, "side entry: the cup's height solved so the pick's approach clears the floor; "
                      "slides overhung at every staging pose tried last"),
    ("panda", FREE, "the gripper's side entry, which the arm's hand follows"),
    ("panda", ARTICULATED, "a door's turn that no base placement reaches whole is cut up to the stall angle "
                           "short, and the hand lets go there"),
    ("panda", FREE, "a slide into a cavity that the forearm cannot finish is let go up to 8 cm short of its end"),
)


class OlderExecutorError(ValueError):
    """A run that a report needs was carried out by an older version of its executor."""


def executor_version(executor: str, task: str) -> int:
    """The version of ``executor``'s path for the stages of ``task`` (a task this process does
    not know counts as having every kind of stage)."""
    info = TASKS.get(task)
    kinds = set(info.stages) if info is not None else None
    return 1 + sum(1 for name, kind, _ in EXECUTOR_CHANGES
                   if name == executor and (kinds is None or kind in kinds))


def older_executor_reason(run_dir: str | Path) -> str | None:
    """One line saying why the run in ``run_dir`` was carried out by an older version of its
    executor than today's, or None when it is current or has no readable ``run.json``."""
    stored = stored_run_config(run_dir)
    if stored is None or not isinstance(stored.get("task"), str):
        return None
    executor = stored.get("executor", "ideal")
    version = stored.get("executor_version", 1)
    current = executor_version(executor, stored["task"])
    if version == current:
        return None
    return (f"{Path(run_dir)} was carried out by version {version} of the {executor} executor for "
            f"{stored['task']}, and today's is version {current}; score it again")
