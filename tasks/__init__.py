"""wpbench tasks. Importing this package registers the built-in tasks with gymnasium:
``gym.make("wpbench/OpenDoor-v0")``, ``"wpbench/PlaceIn-v0"``, ``"wpbench/OpenThenPlace-v0"``.

Their command-line names live in ``wpbench.names.TASKS``. To add a task, see
``docs/adding-a-task.md``: one file here with a ``CrossPoseEnv`` subclass decorated by
``@register_env("wpbench/<Name>-v0", max_episode_steps=<number of stages>)``, and one
``register_task`` line in ``wpbench/names.py``.
"""

from wpbench.tasks.open_door import OpenDoorEnv
from wpbench.tasks.open_then_place import OpenThenPlaceEnv
from wpbench.tasks.place_in import PlaceInEnv

__all__ = ["OpenDoorEnv", "PlaceInEnv", "OpenThenPlaceEnv"]
