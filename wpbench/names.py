"""Every name wpbench is built from, in one light module: tasks, kinds, splits,
observation modes, executors and policy groups.

The CLI, the paper table, the data config, the scripts and the tasks read them from
here, so a name is written once. Importing this module imports nothing heavy (no
torch, no SAPIEN): command-line callbacks and ``--help`` use it.

A task is added in two steps (``docs/adding-a-task.md``): a file with an env class
registered with ManiSkill3's ``@register_env``, and a :func:`register_task` call that
gives it a command-line name. The built-in tasks are listed below; tasks of your own
are registered by a module of yours named in the ``WPBENCH_PLUGINS`` environment
variable (comma-separated module names), which :func:`load_plugins` imports.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass

# Kinds of goal. The observation a policy gets never says which one a stage is; only the
# privileged policies learn it, from the env's ground truth.
ARTICULATED = "articulated"
FREE = "free-floating"
KINDS = (ARTICULATED, FREE)
KIND_CODE = {ARTICULATED: 0, FREE: 1}

# Furniture splits of the built-in library. "all" (runs only) means every instance.
SPLITS = ("train", "val", "test")
RUN_SPLITS = (*SPLITS, "all")

OBS_MODES = ("camera", "mesh")

# How a predicted cross-pose is carried out in the simulator.
EXECUTORS = ("ideal", "gripper", "panda")
# The executor of `wpbench run` and `wpbench sweep` when none is named: the most realistic one
# that meets the benchmark's capability and speed bars (docs/executors.md). The task envs and
# RunConfig keep "ideal", the teleport protocol, as their own default.
DEFAULT_EXECUTOR = "gripper"

# Policy groups. The registry (wpbench.policies.registry) maps each name to its class.
TRAINABLE_POLICIES = ("gf", "tp", "wp-og", "wp-postsvd", "wp-postsvd-t")
WEIGHTED_POSE_VARIANTS = ("wp-og", "wp-postsvd", "wp-postsvd-t")
BEST_WEIGHTED_POSE = "wp"  # alias of the variant named in policies/weights/best.json
# Policies that may read ground truth (the kind of goal, the true cross-pose).
PRIVILEGED_POLICIES = ("gt", "oracle")
# Policies that load trained weights (and so take --weights-root, --subsets, --mirror-views).
WEIGHTED_POLICIES = (*TRAINABLE_POLICIES, BEST_WEIGHTED_POSE, "oracle")

PLUGINS_VARIABLE = "WPBENCH_PLUGINS"


@dataclass(frozen=True)
class TaskInfo:
    """A task's command-line name, its gymnasium id, the module that registers the id,
    and its stages (one kind each, in order)."""

    name: str
    env_id: str
    module: str
    stages: tuple[str, ...]

    def __post_init__(self) -> None:
        if not self.stages or any(kind not in KINDS for kind in self.stages):
            raise ValueError(f"task {self.name!r}: stages must be a non-empty sequence of {KINDS}, got {self.stages!r}")


TASKS: dict[str, TaskInfo] = {}


def register_task(name: str, env_id: str, module: str, stages: tuple[str, ...]) -> TaskInfo:
    """Give the env ``env_id`` (registered when ``module`` is imported) the command-line name ``name``."""
    info = TaskInfo(name, env_id, module, tuple(stages))
    known = TASKS.get(name)
    if known is not None and known != info:
        raise ValueError(f"task name {name!r} is taken by {known.env_id} ({known.module}); choose another name")
    TASKS[name] = info
    return info


register_task("open-door", "wpbench/OpenDoor-v0", "wpbench.tasks.open_door", (ARTICULATED,))
register_task("place-in", "wpbench/PlaceIn-v0", "wpbench.tasks.place_in", (FREE,))
register_task("open-then-place", "wpbench/OpenThenPlace-v0", "wpbench.tasks.open_then_place", (ARTICULATED, FREE))
BUILTIN_TASKS = tuple(TASKS)

# The task that samples each kind's training data (wpbench data generate).
KIND_TASK = {ARTICULATED: "open-door", FREE: "place-in"}


def load_plugins() -> list[str]:
    """Import the modules named in ``$WPBENCH_PLUGINS`` (they call :func:`register_task`).

    Returns their names. An unimportable module is an error that names the variable.
    """
    names = [n.strip() for n in os.environ.get(PLUGINS_VARIABLE, "").split(",") if n.strip()]
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError as err:
            raise ValueError(f"{PLUGINS_VARIABLE} names module {name!r}, which cannot be imported ({err}); "
                             "put it on PYTHONPATH or fix the variable") from err
    return names


def task_names() -> tuple[str, ...]:
    """Every task's command-line name, plugins included."""
    load_plugins()
    return tuple(TASKS)


def task_info(name: str) -> TaskInfo:
    """The task called ``name``; ValueError listing the valid names otherwise."""
    names = task_names()
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; valid: {', '.join(names)}")
    return TASKS[name]


def import_task(name: str) -> TaskInfo:
    """Import the module that registers task ``name``'s env with gymnasium; returns its info."""
    info = task_info(name)
    importlib.import_module(info.module)
    return info
