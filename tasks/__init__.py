"""wpbench tasks. Importing this package registers them with gymnasium:
``gym.make("wpbench/OpenDoor-v0")``, ``"wpbench/PlaceIn-v0"``, ``"wpbench/OpenThenPlace-v0"``.

To add a task: write one file here with a ``CrossPoseEnv`` subclass decorated by
``@register_env("wpbench/<Name>-v0", max_episode_steps=<number of stages>)``,
import it below, and add its CLI name to ``TASKS``.
"""

from wpbench.tasks.open_door import OpenDoorEnv
from wpbench.tasks.open_then_place import OpenThenPlaceEnv
from wpbench.tasks.place_in import PlaceInEnv

# CLI name -> gymnasium id
TASKS = {
    "open-door": "wpbench/OpenDoor-v0",
    "place-in": "wpbench/PlaceIn-v0",
    "open-then-place": "wpbench/OpenThenPlace-v0",
}

__all__ = ["OpenDoorEnv", "PlaceInEnv", "OpenThenPlaceEnv", "TASKS"]
