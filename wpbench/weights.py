"""Trained weights: where the shipped ones live, what a trained policy is made of, how it is
loaded, hashed and promoted, and which WeightedPose variant ``wp`` means.

A trained policy is a folder holding

- ``model.pt``: the model's ``state_dict`` (float32 tensors only, loaded with ``weights_only``);
- ``config.json``: the policy's name, model name + full model config, loss preset, the point
  counts it was trained with, the data manifest hashes and ``model_hash`` (:func:`model_hash`);
- ``metrics.json``: final validation errors by kind, wall time, peak memory;
- and, from the training, ``progress.json`` (``"status": "done"`` once it finished),
  ``train_log.csv`` and ``train_log.png``.

The shipped weights are such folders under ``policies/weights/<policy>/`` (the package
``wpbench.policies``, located here without importing it), with ``best.json`` naming the
best WeightedPose variant. ``wpbench train`` writes a run folder elsewhere
(``runs/train/<policy>/``); :func:`promote` is the one way a run becomes shipped weights.
Both ``wpbench.training`` and ``wpbench.policies`` import this module, never each other.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import json
import math
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

from wpbench.names import TRAINABLE_POLICIES, WEIGHTED_POSE_VARIANTS

FORMAT_VERSION = 1
MODEL_FILE, CONFIG_FILE, METRICS_FILE = "model.pt", "config.json", "metrics.json"
PROGRESS_FILE = "progress.json"
# What a training leaves besides the three files above, copied along when present.
TRAINING_RECORDS = ("progress.json", "train_log.csv", "train_log.png")
CHECKPOINT_FILE = "checkpoint.pt"
BEST_FILE = "best.json"
# The criterion that chooses the best WeightedPose variant (lower is better).
CRITERION = "val_mean_point_m"
# What ``wp`` means when no best.json has been written.
FALLBACK_WEIGHTED_POSE = "wp-postsvd-t"
# The validation numbers a promoted run must have, finite, for every kind.
VALIDATION_ERRORS = ("rot_deg", "trans_m", "point_m")
HASH_CHARS = 16

if TYPE_CHECKING:  # torch is imported where tensors are handled, so reading best.json stays light
    import torch


def shipped_weights_root() -> Path:
    """``policies/weights``: the folder of the package ``wpbench.policies``, found without importing it."""
    spec = importlib.util.find_spec("wpbench.policies")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("the package wpbench.policies is not installed; reinstall wpbench (pip install -e .)")
    return Path(list(spec.submodule_search_locations)[0]).resolve() / "weights"


def weights_root_or_shipped(weights_root: Path | str | None) -> Path:
    """``weights_root`` as a Path, or the shipped weights when it is None."""
    return Path(weights_root) if weights_root is not None else shipped_weights_root()


# --- writing ----------------------------------------------------------------------------------

def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file, so a reader sees the old or the new file."""
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_torch_save(obj: Any, path: Path) -> None:
    """``torch.save`` through a temporary file (see :func:`atomic_write_text`)."""
    import torch

    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def config_to_json(config: Any) -> dict:
    """A model config dataclass -> JSON-able dict (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


def model_hash(state: dict[str, torch.Tensor]) -> str:
    """The first 16 hex digits of the SHA-256 of a state_dict's floating-point tensors as float32
    bytes, in the state_dict's order (what ``config.json`` records as ``model_hash``)."""
    data = b"".join(v.detach().float().contiguous().numpy().tobytes() for v in state.values() if v.is_floating_point())
    return hashlib.sha256(data).hexdigest()[:HASH_CHARS]


def save_trained(out: Path, model: torch.nn.Module, description: dict, metrics: dict) -> None:
    """Write model.pt (float32 state_dict), config.json (``description`` + format + model_hash) and
    metrics.json into ``out``."""
    import torch

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().to(torch.float32).contiguous().clone() if v.is_floating_point() else v.detach().clone()
             for k, v in model.state_dict().items()}
    config = {"format": FORMAT_VERSION, **description, "model_hash": model_hash(state)}
    atomic_torch_save(state, out / MODEL_FILE)
    atomic_write_text(out / CONFIG_FILE, json.dumps(config, indent=2, sort_keys=True) + "\n")
    atomic_write_text(out / METRICS_FILE, json.dumps(metrics, indent=2, sort_keys=True) + "\n")


# --- loading ----------------------------------------------------------------------------------

def _train_command(policy: str) -> str:
    return f"`wpbench train --policy {policy}`"


def read_config(weights_dir: Path, policy: str | None = None) -> dict:
    """``config.json`` of a trained policy; clear errors naming the command that makes it."""
    weights_dir = Path(weights_dir)
    policy = policy or weights_dir.name
    path = weights_dir / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no trained weights for {policy!r}: {path} is missing; make them with {_train_command(policy)}")
    try:
        config = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path} is corrupt ({err}); retrain with {_train_command(policy)}") from err
    if not isinstance(config, dict) or config.get("format") != FORMAT_VERSION or "model" not in config:
        raise ValueError(f"{path} is not a wpbench model config (format {FORMAT_VERSION}); retrain with {_train_command(policy)}")
    return config


def load_state(weights_dir: Path, policy: str | None = None) -> dict[str, torch.Tensor]:
    """``model.pt`` of a trained policy as a state_dict."""
    import torch

    weights_dir = Path(weights_dir)
    policy = policy or weights_dir.name
    path = weights_dir / MODEL_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no trained weights for {policy!r}: {path} is missing; make them with {_train_command(policy)}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - any unpickling failure means a corrupt file
        reason = (str(err).strip().splitlines() or [type(err).__name__])[-1][:200]
        raise ValueError(f"{path} is corrupt or not a model file ({reason}); retrain with {_train_command(policy)}") from err
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise ValueError(f"{path} does not hold a state_dict; retrain with {_train_command(policy)}")
    return state


def build_from_config(config: dict) -> torch.nn.Module:
    """A freshly initialised model as described by a ``config.json`` dict."""
    from wpbench.models.registry import build_model, saved_model_config

    cfg = saved_model_config(config["model"], config["model_config"])
    return build_model(config["model"], config=cfg)


def load_trained_model(weights_dir: Path, policy: str | None = None) -> tuple[torch.nn.Module, dict]:
    """(model in eval mode with its trained weights, its config.json dict) from a trained policy's folder."""
    policy = policy or Path(weights_dir).name
    config = read_config(weights_dir, policy)
    try:
        model = build_from_config(config)
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{Path(weights_dir) / CONFIG_FILE} describes no buildable model ({err}); "
                         f"retrain with {_train_command(policy)}") from err
    state = load_state(weights_dir, policy)
    mismatch = _state_mismatch(model.state_dict(), state)
    if mismatch:
        raise ValueError(f"{Path(weights_dir) / MODEL_FILE} does not match its config.json ({mismatch}); "
                         f"retrain with {_train_command(policy)}")
    model.load_state_dict(state, strict=True)
    model.eval()
    return model, config


def _state_mismatch(expected: dict[str, torch.Tensor], state: dict[str, torch.Tensor]) -> str:
    """How ``state`` differs from the tensors a model expects, in one line ("" when it fits)."""
    missing = [k for k in expected if k not in state]
    unexpected = [k for k in state if k not in expected]
    reshaped = [k for k in expected if k in state and expected[k].shape != state[k].shape]
    parts = [f"{len(keys)} {what}, e.g. {keys[0]!r}"
             for keys, what in ((missing, "tensors missing"), (unexpected, "unexpected tensors"),
                                (reshaped, "tensors of another shape")) if keys]
    return "; ".join(parts)


# --- best.json ----------------------------------------------------------------------------------

def best_weighted_pose(weights_root: Path | None = None) -> str:
    """The variant ``best.json`` names, or ``FALLBACK_WEIGHTED_POSE`` when there is no best.json."""
    path = weights_root_or_shipped(weights_root) / BEST_FILE
    if not path.is_file():
        return FALLBACK_WEIGHTED_POSE
    try:
        name = json.loads(path.read_text())["policy"]
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{path} is corrupt ({err}); rewrite it with `wpbench train --select-best`") from err
    if name not in WEIGHTED_POSE_VARIANTS:
        raise ValueError(f"{path} names {name!r}, not a WeightedPose variant; rewrite it with `wpbench train --select-best`")
    return name


def _val_data_of(weights_dir: Path) -> str | None:
    """The val manifest hash a trained policy's validation errors were measured on (None if unrecorded)."""
    try:
        data = json.loads((weights_dir / CONFIG_FILE).read_text()).get("data")
    except (OSError, ValueError, AttributeError):
        return None
    return data.get("val_manifest_hash") if isinstance(data, dict) else None


def select_best(weights_root: Path | None = None) -> dict | None:
    """Write ``best.json`` naming the trained variant with the lowest ``CRITERION`` in its
    metrics.json; None (and no file written) if no variant is trained. ValueError (and no file
    written) if the variants' errors were measured on different val data: they do not compare."""
    weights_root = weights_root_or_shipped(weights_root)
    candidates: dict[str, float] = {}
    for name in WEIGHTED_POSE_VARIANTS:
        path = weights_root / name / METRICS_FILE
        if not path.is_file():
            continue
        try:
            value = float(json.loads(path.read_text())[CRITERION])
        except (ValueError, KeyError, TypeError, json.JSONDecodeError):
            continue
        if math.isfinite(value):
            candidates[name] = value
    if not candidates:
        return None
    val_data = {name: _val_data_of(weights_root / name) for name in candidates}
    if len(set(val_data.values())) > 1:
        listed = ", ".join(f"{name} on val data {val_data[name]}" for name in sorted(val_data))
        raise ValueError(f"the WeightedPose variants under {weights_root} were validated on different data ({listed}), "
                         "so their errors do not compare; retrain them on the same data, then `wpbench train --select-best`")
    best = min(candidates, key=candidates.get)
    record = {"policy": best, "criterion": f"{CRITERION} (lower is better)", "candidates": candidates}
    atomic_write_text(weights_root / BEST_FILE, json.dumps(record, indent=2, sort_keys=True) + "\n")
    return record


# --- promotion ----------------------------------------------------------------------------------

def _read_json(path: Path, what: str, fix: str) -> Any:
    if not path.is_file():
        raise ValueError(f"{path} is missing, so {what}; {fix}")
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path} is corrupt ({err}); {fix}") from err


def check_run(run_dir: Path) -> dict:
    """Check that ``run_dir`` holds a finished training fit to ship; returns its config.json.

    It must have ``model.pt``, a ``config.json`` naming a trainable policy whose model builds and
    loads ``model.pt`` (with the recorded ``model_hash``), a ``metrics.json`` with finite validation
    errors for every kind, and ``progress.json`` saying the training is done (not a checkpoint of
    an interrupted run). ValueError otherwise, saying what to do.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ValueError(f"no run folder {run_dir}; train one with `wpbench train --policy NAME` (it writes runs/train/NAME)")
    try:
        config = read_config(run_dir)
    except (FileNotFoundError, ValueError) as err:
        raise ValueError(f"{run_dir} is not a trained policy: {err}") from err
    policy = config.get("policy")
    if policy not in TRAINABLE_POLICIES:
        raise ValueError(f"{run_dir / CONFIG_FILE} names policy {policy!r}, not one of {', '.join(TRAINABLE_POLICIES)}; "
                         "promote a run of `wpbench train --policy NAME`")
    resume = f"resume it with `wpbench train --policy {policy} --out {run_dir}`"
    if not (run_dir / MODEL_FILE).is_file():
        unfinished = " holds only a checkpoint" if (run_dir / CHECKPOINT_FILE).is_file() else " has no model.pt"
        raise ValueError(f"{run_dir}{unfinished}: the training did not finish; {resume}")
    progress = _read_json(run_dir / PROGRESS_FILE, "the run cannot show that its training finished", resume)
    if not isinstance(progress, dict) or progress.get("status") != "done":
        status = progress.get("status") if isinstance(progress, dict) else None
        raise ValueError(f"{run_dir / PROGRESS_FILE} says the training is {status!r}, not 'done'; {resume}")
    metrics = _read_json(run_dir / METRICS_FILE, "the run has no validation numbers", resume)
    _check_metrics(run_dir / METRICS_FILE, metrics, policy)
    try:
        model, _ = load_trained_model(run_dir, policy)
    except (FileNotFoundError, ValueError) as err:
        raise ValueError(f"{run_dir} cannot be promoted: {err}") from err
    recorded, actual = config.get("model_hash"), model_hash(model.state_dict())
    if recorded != actual:
        raise ValueError(f"{run_dir / MODEL_FILE} has model_hash {actual}, but config.json records {recorded!r}: the "
                         f"files come from different trainings; retrain with `wpbench train --policy {policy} --restart`")
    return config


def _check_metrics(path: Path, metrics: Any, policy: str) -> None:
    retrain = f"retrain with `wpbench train --policy {policy} --restart`"
    val = metrics.get("val") if isinstance(metrics, dict) else None
    if not isinstance(val, dict) or not val:
        raise ValueError(f"{path} has no validation errors ('val'); {retrain}")
    numbers = {f"val.{kind}.{key}": (values or {}).get(key) if isinstance(values, dict) else None
               for kind, values in val.items() for key in VALIDATION_ERRORS}
    numbers[CRITERION] = metrics.get(CRITERION)
    bad = [name for name, value in numbers.items()
           if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value)]
    if bad:
        raise ValueError(f"{path} has no finite {', '.join(bad)}: the model's predictions failed; {retrain}")


def promote(run_dir: Path, weights_root: Path | None = None) -> dict:
    """Ship the finished training in ``run_dir`` (see :func:`check_run`) as ``<weights_root>/<policy>/``.

    The files (model.pt, config.json, metrics.json and the training records) are copied into a
    temporary folder beside the target, which then takes the target's place by renames, so the
    folder never holds a mix of old and new files (the old ones are restored if the rename fails). For a WeightedPose variant ``best.json`` is chosen
    again. Returns {"policy", "weights_dir", "model_hash", "best", "best_unchanged"} (best: the
    best.json record or None; best_unchanged: why best.json was left as it was, or None).
    """
    run_dir = Path(run_dir)
    config = check_run(run_dir)
    policy = config["policy"]
    weights_root = weights_root_or_shipped(weights_root)
    target = weights_root / policy
    if target.exists() and target.resolve() == run_dir.resolve():
        raise ValueError(f"{run_dir} already is the shipped {policy!r}; promote a run folder (runs/train/{policy})")
    weights_root.mkdir(parents=True, exist_ok=True)
    staging = weights_root / f".{policy}.promote-{os.getpid()}"
    replaced = weights_root / f".{policy}.replaced-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        for name in (MODEL_FILE, CONFIG_FILE, METRICS_FILE, *TRAINING_RECORDS):
            if (run_dir / name).is_file():
                shutil.copy2(run_dir / name, staging / name)
        if target.exists():
            os.replace(target, replaced)
        try:
            os.replace(staging, target)
        except OSError:
            if replaced.exists():
                os.replace(replaced, target)  # put the shipped weights back
            raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        shutil.rmtree(replaced, ignore_errors=True)
    best, best_unchanged = None, None
    if policy in WEIGHTED_POSE_VARIANTS:
        try:
            best = select_best(weights_root)
        except ValueError as err:  # the weights are shipped; best.json stays as it was
            best_unchanged = str(err)
    return {"policy": policy, "weights_dir": target, "model_hash": config["model_hash"], "best": best,
            "best_unchanged": best_unchanged}
