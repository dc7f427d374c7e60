"""Training data for the cross-pose models, sampled from the wpbench tasks.

Layout on disk (``wpbench data generate --out data/ --split train``)::

    data/<split>/manifest.json              config, shard list, counts by kind/category
    data/<split>/<kind>/shard-00000.npz     SHARD_SIZE samples each, written atomically

- ``config``: :class:`GenerationConfig` (what to sample and how).
- ``shards``: one shard file <-> a dict of stacked sample arrays (schema in ``shards``).
- ``manifest``: the index of a split directory, rebuilt from the shards on disk.
- ``generate``: runs the tasks (OpenDoor-v0 / PlaceIn-v0) and writes shards, resumably.
- ``dataset``: a torch ``Dataset`` over a split, all samples held in memory.
- ``augment``: random yaw of a whole scene, applied to points and ground truth alike.
"""
