"""Training of the learned policies (``wpbench train --policy NAME``).

- ``specs``: which model, loss preset, data kinds and starting weights each policy uses.
- ``config``: :class:`TrainConfig` (budget, batch, learning rate, point counts).
- ``batches``: shuffling, point subsampling and augmentation of training batches.
- ``data_mix``: several data sets in one training (``--data A:0.7 --data B:0.3``): weighted
  sampling, compatibility checks, what ``config.json`` records of the mix.
- ``evaluate``: validation errors (rotation deg, translation m, point error m) per kind.
- ``checkpoint``: save / resume the full training state.
- ``log``: ``train_log.csv``, ``progress.json`` and the ``train_log.png`` plot.
- ``loop``: the trainer that ties them together; it writes the run folder
  (``runs/train/<policy>/`` by default).

The files of a trained policy, loading, hashing, ``best.json`` and the promotion of a run into
the shipped weights are ``wpbench.weights``. Training never imports ``wpbench.policies``.
"""
