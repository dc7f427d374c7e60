"""``results/paper-table.md``: the layout of the WeightedPose paper's Table 1,
plus what the simulator says.

Four tables, one command (``wpbench paper-table``):

1. Pose errors on the generated data set (no simulation): for each policy, the
   train and val splits, free-floating and articulated samples, mean rotation
   error (deg), translation error (cm) and per-point error (cm).
2. Val pose errors by furniture category, per kind.
3. Simulated success rate (95% Wilson interval) of each policy on every task,
   val split, built-in furniture, one row per policy and executor: read from the runs'
   folders (``RunConfig.default_out``: ``results/runs/<policy>__<task>__val__procedural__<obs>``,
   plus ``__<executor>`` for another executor than ``ideal``) and, with ``run_missing``,
   run there first for ``executors``: every missing or short run in one sweep
   (``wpbench.evaluation.sweep``), all their episodes on one pool (``workers`` local
   processes or a Ray cluster), each run resumable, the leaderboard rebuilt after.
   An executor other than ``ideal`` has rows only when it has runs.
4. The same on the test split and on the real PartNet-Mobility objects, where those runs
   exist (``...__test__procedural__<obs>``, scored once per release by an explicit sweep;
   ``...__val__partnet-mobility__<obs>``, made by ``scripts/reference_runs.sh``: how far
   policies trained on the built-in furniture carry to furniture they never saw), and the
   real-object runs' successes per object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from wpbench.models.configs import DEFAULT_MIRROR_VIEWS, DEFAULT_SUBSETS

from wpbench.names import ARTICULATED, BUILTIN_TASKS, EXECUTORS, FREE, WEIGHTED_POSE_VARIANTS

POLICIES = ("gf", "tp", "oracle", *WEIGHTED_POSE_VARIANTS)
TASKS = BUILTIN_TASKS
KINDS = (FREE, ARTICULATED)  # the paper's column order
SPLITS = ("train", "val")    # data splits whose pose errors the table reports
REAL_SOURCE = "partnet-mobility"  # the run-directory name of ../shared/partnet-mobility


@dataclass
class PaperTableConfig:
    data: Path = Path("data")
    samples_per_kind: int = 200
    episodes: int = 100
    obs: str = "camera"
    run_missing: bool = True
    results: Path = Path("results")
    policies: tuple[str, ...] = POLICIES
    subsets: int = DEFAULT_SUBSETS  # random subsets per sample, fused, as the learned policies answer
    mirror_views: bool = DEFAULT_MIRROR_VIEWS  # every second subset answered in the mirrored scene, as they do
    workers: int | None = 1  # local worker processes for the missing runs (None: one per core)
    use_ray: bool = False  # run the missing runs on a Ray cluster instead
    ray_address: str | None = None  # that cluster (None: a local one)
    executors: tuple[str, ...] = ("ideal",)  # whose missing val runs ``run_missing`` runs; rows show every executor run


def _oracle_specialists() -> dict[str, str]:
    """{kind: policy} the oracle routes each kind to (its config's defaults)."""
    from wpbench.policies.oracle import OracleConfig

    oracle = OracleConfig()
    return {FREE: oracle.free_policy, ARTICULATED: oracle.articulated_policy}


def _policies_for(policy: str, cfg: PaperTableConfig) -> dict[str, object]:
    """{kind: the LearnedPolicy answering that kind for ``policy``} (the oracle routes each kind to
    its specialist). The pose errors use each one's model, point counts, seed, subsets and mirrored
    views, so they measure what the policy answers in the simulator."""
    from wpbench.policies.learned import LearnedPolicy

    def loaded(name: str) -> LearnedPolicy:
        return LearnedPolicy(policy=name, subsets=cfg.subsets, mirror_views=cfg.mirror_views)

    if policy == "oracle":
        return {kind: loaded(name) for kind, name in _oracle_specialists().items()}
    learned = loaded(policy)
    return {kind: learned for kind in KINDS}


def _as_policy(learned) -> dict:
    """The ``wpbench.training.evaluate`` arguments that answer as ``learned`` does."""
    return {"num_action": learned.num_action_points, "num_anchor": learned.num_anchor_points,
            "seed": learned.config.seed, "subsets": learned.config.subsets,
            "mirror_views": learned.config.mirror_views}


def pose_errors(cfg: PaperTableConfig, policy: str) -> dict[tuple[str, str], dict[str, float]]:
    """{(split, kind): {"rot_deg", "trans_m", "point_m", "n"}} on the data set."""
    from wpbench.data.dataset import CrossPoseDataset
    from wpbench.training.evaluate import evaluate

    learned = _policies_for(policy, cfg)
    out = {}
    for split in SPLITS:
        directory = Path(cfg.data) / split
        for kind in KINDS:
            dataset = CrossPoseDataset(directory, kinds=(kind,))
            out[(split, kind)] = evaluate(learned[kind].model, dataset, (kind,), cfg.samples_per_kind,
                                          **_as_policy(learned[kind]))[kind]
    return out


def training_data(cfg: PaperTableConfig, policy: str) -> str:
    """What ``policy``'s weights were trained on, from their config.json (the oracle: both
    specialists'); reads no model."""
    from wpbench.training.data_mix import describe_data
    from wpbench.weights import read_config, shipped_weights_root

    def of(name: str) -> str:
        config = read_config(shipped_weights_root() / name, name)
        train_config = config.get("train_config") or {}
        past_stop, cap = train_config.get("door_past_stop_deg", 0.0), train_config.get("door_max_turn_deg")
        capped = f" (at most {cap:g} deg in all)" if cap is not None else ""
        return describe_data(config.get("data") or {}) + (f", door goals {past_stop:g} deg past the stop{capped}" if past_stop else "")

    if policy == "oracle":
        return "; ".join(f"{kind}: {name} {of(name)}" for kind, name in _oracle_specialists().items())
    return of(policy)


def category_errors(cfg: PaperTableConfig, policy: str) -> dict[str, dict[str, dict[str, float]]]:
    """{kind: {category: errors}} on every val sample: where a policy fails, not only how much."""
    from wpbench.data.dataset import CrossPoseDataset
    from wpbench.training.evaluate import evaluate_by_category

    learned = _policies_for(policy, cfg)
    out = {}
    for kind in KINDS:
        dataset = CrossPoseDataset(Path(cfg.data) / "val", kinds=(kind,))
        out[kind] = evaluate_by_category(learned[kind].model, dataset, kind, **_as_policy(learned[kind]))
    return out


def run_dir(cfg: PaperTableConfig, policy: str, task: str, source: str = "procedural", split: str = "val",
            executor: str = "ideal") -> Path:
    """Where ``wpbench run`` puts that run by default (clean camera)."""
    from wpbench.evaluation.runner import RunConfig

    assets = "procedural" if source == "procedural" else source
    return RunConfig(policy=policy, task=task, split=split, assets=assets, obs=cfg.obs,
                     executor=executor).default_out(cfg.results)


def _read_summary(directory: Path) -> dict | None:
    import json

    from wpbench.evaluation.executor_version import OlderExecutorError, older_executor_reason
    from wpbench.evaluation.furniture_version import OtherFurnitureError, other_furniture_reason

    reason = other_furniture_reason(directory)
    if reason:
        raise OtherFurnitureError(reason)
    reason = older_executor_reason(directory)
    if reason:
        raise OlderExecutorError(reason)
    summary_file = directory / "summary.json"
    return json.loads(summary_file.read_text()) if summary_file.is_file() else None


def real_success(cfg: PaperTableConfig, policy: str, task: str, executor: str = "ideal") -> dict | None:
    """The run's summary on the real objects, or None (never run from here: it needs their folder)."""
    return _read_summary(run_dir(cfg, policy, task, REAL_SOURCE, executor=executor))


def real_per_object(cfg: PaperTableConfig, policy: str, task: str, executor: str = "ideal") -> dict | None:
    """The real-object run's successes per object, ``{object_id: (category, successes, episodes)}``,
    or None when it was never run (read from its ``episodes.jsonl``)."""
    from wpbench.evaluation.records import read_episodes

    directory = run_dir(cfg, policy, task, REAL_SOURCE, executor=executor)
    if _read_summary(directory) is None:
        return None
    counts: dict[str, tuple[str, int, int]] = {}
    for record in read_episodes(directory):
        name = str(record.get("object_id"))
        category, wins, n = counts.get(name, (str(record.get("category")), 0, 0))
        counts[name] = (category, wins + bool(record.get("success")), n + 1)
    return counts


def _per_object_table(cfg: PaperTableConfig, per_object: dict) -> list[str]:
    """``per_object``: {(policy, executor, task): {object_id: (category, successes, episodes)}}.
    A row per policy and executor with real-object runs, a column per object; a cell gives the
    successes / episodes of each task in TASKS order ("-" where that task was not run)."""
    objects = sorted({(cat, name) for counts in per_object.values() for name, (cat, _, _) in counts.items()})
    lines = ["", "## Real PartNet-Mobility objects, per object",
             "", "Successes / episodes on each object, " + " · ".join(TASKS) + ".", "",
             "| policy | executor | " + " | ".join(f"{name} ({cat})" for cat, name in objects) + " |",
             "|" + "---|" * (2 + len(objects))]
    for policy in cfg.policies:
        for executor in EXECUTORS:
            if not any((policy, executor, task) in per_object for task in TASKS):
                continue
            cells = []
            for _, name in objects:
                parts = []
                for task in TASKS:
                    got = per_object.get((policy, executor, task), {}).get(name)
                    parts.append("-" if got is None else f"{got[1]}/{got[2]}")
                cells.append(" · ".join(parts))
            lines.append(f"| {policy} | {executor} | " + " | ".join(cells) + " |")
    return lines


def test_success(cfg: PaperTableConfig, policy: str, task: str, executor: str = "ideal") -> dict | None:
    """The run's summary on the test split, or None. Never run from here: test is scored once
    per release of the weights, by an explicit sweep, after every choice is made (docs/design.md)."""
    return _read_summary(run_dir(cfg, policy, task, split="test", executor=executor))


def camera_settings(summaries: list[dict]) -> str:
    """What camera the runs of the table saw: "a clean camera" or the noise settings they name."""
    from wpbench.sim.camera_noise import CameraNoise

    tags = sorted({CameraNoise.from_settings((s.get("meta") or {}).get("camera_noise") or {}).tag() for s in summaries})
    named = [tag for tag in tags if tag]
    return "a clean camera" if not named else "camera noise " + ", ".join(named) + (" and a clean camera" if "" in tags else "")


def success(cfg: PaperTableConfig, policy: str, task: str, executor: str = "ideal") -> dict | None:
    """The val run's summary as it is on disk, or None when it was never run."""
    return _read_summary(run_dir(cfg, policy, task, executor=executor))


def missing_runs(cfg: PaperTableConfig, policies: tuple[str, ...] | list[str]):
    """RunConfigs (resumable, in ``run_dir``) of the built-in-furniture runs of ``policies``
    that are missing or hold fewer than ``cfg.episodes`` episodes."""
    from wpbench.evaluation.sweep import sweep_configs

    configs = []
    for policy in policies:
        for executor in cfg.executors:
            for task in TASKS:
                summary = success(cfg, policy, task, executor)
                if summary is None or summary.get("episodes", 0) < cfg.episodes:
                    (config,) = sweep_configs([policy], [task], cfg.episodes, cfg.results, executors=[executor],
                                              obs=cfg.obs)
                    configs.append(config)
    return configs


def run_missing(cfg: PaperTableConfig, policies: tuple[str, ...] | list[str]) -> list[dict]:
    """Run every missing or short run of ``policies`` in one sweep; their summaries."""
    configs = missing_runs(cfg, policies)
    if not configs:
        return []
    from wpbench.evaluation.sweep import run_sweep

    return run_sweep(configs, cfg.results, workers=cfg.workers, use_ray=cfg.use_ray, ray_address=cfg.ray_address)


def _fmt(value: float, scale: float = 1.0, digits: int = 1) -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value * scale:.{digits}f}"


def _success_table(cfg: PaperTableConfig, title: str, successes: dict) -> list[str]:
    """``successes``: {(policy, executor, task): summary}. A row per policy and executor; the
    ``ideal`` rows always, another executor's only when it has a run in this table."""
    executors = [e for e in EXECUTORS if e == "ideal" or any(key[1] == e for key in successes)]
    lines = ["", title, "", "| policy | executor | " + " | ".join(TASKS) + " |", "|" + "---|" * (2 + len(TASKS))]
    for policy in cfg.policies:
        for executor in executors:
            cells = []
            for task in TASKS:
                s = successes.get((policy, executor, task))
                if s is None:
                    cells.append("not run")
                else:
                    lo, hi = s["success_ci95"]
                    cells.append(f"{100 * s['success_rate']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}] (n={s['episodes']})")
            lines.append(f"| {policy} | {executor} | " + " | ".join(cells) + " |")
    return lines


def render(cfg: PaperTableConfig, errors: dict, successes: dict, by_category: dict | None = None,
           real_successes: dict | None = None, test_successes: dict | None = None,
           trained_on: dict | None = None, real_per_object: dict | None = None) -> str:
    """``successes`` / ``real_successes`` / ``test_successes``: {(policy, executor, task): summary}
    on the built-in val furniture / the real objects / the built-in test furniture (those two
    sections only when there is at least one such run). ``trained_on``: {policy: what its
    weights were trained on} (a section of its own when given). ``real_per_object``: the real
    runs' successes per object (see :func:`_per_object_table`; a section when given)."""
    by_category = by_category or {}
    test_successes = test_successes or {}
    seen = [*successes.values(), *(real_successes or {}).values(), *test_successes.values()]
    lines = ["# WeightedPose, paper Table 1 layout (wpbench)", "",
             "Made by `wpbench paper-table`. Pose errors are on the generated data set "
             f"(`{cfg.data}`, up to {cfg.samples_per_kind} samples per split and kind, camera point clouds, "
             f"each answered from {cfg.subsets} random point subsets"
             f"{', every second one mirrored,' if cfg.mirror_views and cfg.subsets > 1 else ''} "
             "fused into one pose as in the benchmark); "
             "success rates are simulated episodes on the val split (unseen built-in furniture), "
             f"obs `{cfg.obs}`, with 95% Wilson intervals, one row per executor that carried out the "
             "poses (`ideal`: the teleport protocol; `gripper`, `panda`: docs/executors.md). "
             f"The runs saw {camera_settings(seen)}; the shipped "
             "weights were trained on camera clouds from a clean camera (no depth noise, holes or "
             "segmentation errors: `wpbench data generate`'s defaults).", "",
             "## Pose errors (rotation deg / translation cm / per-point cm)", ""]
    header = "| policy | " + " | ".join(f"{s} {k}" for s in SPLITS for k in KINDS) + " |"
    lines += [header, "|" + "---|" * (1 + len(SPLITS) * len(KINDS))]
    for policy in cfg.policies:
        if policy not in errors:
            lines.append(f"| {policy} | " + " | ".join("no weights" for _ in range(len(SPLITS) * len(KINDS))) + " |")
            continue
        cells = []
        for split in SPLITS:
            for kind in KINDS:
                e = errors[policy][(split, kind)]
                cells.append(f"{_fmt(e['rot_deg'])} / {_fmt(e['trans_m'], 100)} / {_fmt(e['point_m'], 100)}")
        lines.append(f"| {policy} | " + " | ".join(cells) + " |")
    if trained_on:
        lines += ["", f"The train columns are `{cfg.data}`'s train split, which is a policy's own training data "
                      "only where the two below agree:", "", "| policy | its weights were |", "|---|---|"]
        lines += [f"| {policy} | {trained_on[policy]} |" for policy in cfg.policies if policy in trained_on]
    lines += ["", "## Val pose errors by furniture category (rotation deg / translation cm)", "",
              "Every val sample of the kind the policy is asked about; the rows show where a policy fails.", ""]
    categories = sorted({c for per_kind in by_category.values() for kinds in per_kind.values() for c in kinds})
    lines += ["| policy | kind | " + " | ".join(categories) + " |", "|" + "---|" * (2 + len(categories))]
    for policy in cfg.policies:
        for kind in KINDS:
            per = by_category.get(policy, {}).get(kind)
            if per is None:
                continue
            cells = [f"{_fmt(per[c]['rot_deg'])} / {_fmt(per[c]['trans_m'], 100)}" if c in per else "-" for c in categories]
            lines.append(f"| {policy} | {kind} | " + " | ".join(cells) + " |")
    lines += _success_table(cfg, f"## Simulated success rate (val split, {cfg.obs})", successes)
    if test_successes:
        lines += _success_table(cfg, f"## Simulated success rate (test split, {cfg.obs}; scored once for these "
                                     "weights)", test_successes)
    if real_successes:
        lines += _success_table(cfg, f"## Simulated success rate on real PartNet-Mobility objects ({cfg.obs}; "
                                     "trained on built-in furniture only)", real_successes)
    if real_per_object:
        lines += _per_object_table(cfg, real_per_object)
    return "\n".join(lines) + "\n"


def _refuse_runs_on_other_furniture(cfg: PaperTableConfig) -> None:
    """Raise OtherFurnitureError for the first run the table would read that was scored on
    built-in furniture of another generator version, before the slow pose errors are computed."""
    for policy in cfg.policies:
        for executor in EXECUTORS:
            for task in TASKS:
                for read in (success, test_success):
                    read(cfg, policy, task, executor)


def make_paper_table(cfg: PaperTableConfig, out: Path | None = None) -> Path:
    _refuse_runs_on_other_furniture(cfg)
    errors, successes, by_category, real_successes, test_successes, trained_on = {}, {}, {}, {}, {}, {}
    per_object = {}
    for policy in cfg.policies:
        try:
            errors[policy] = pose_errors(cfg, policy)
            by_category[policy] = category_errors(cfg, policy)
            trained_on[policy] = training_data(cfg, policy)
        except (FileNotFoundError, ValueError) as err:
            print(f"{policy}: no pose errors ({err})")
    if cfg.run_missing:
        run_missing(cfg, [policy for policy in cfg.policies if policy in errors])
    for policy in errors:
        for executor in EXECUTORS:
            for task in TASKS:
                for found, read in ((successes, success), (test_successes, test_success),
                                    (real_successes, real_success)):
                    summary = read(cfg, policy, task, executor)
                    if summary is not None:
                        found[(policy, executor, task)] = summary
                counts = real_per_object(cfg, policy, task, executor)
                if counts is not None:
                    per_object[(policy, executor, task)] = counts
    out = Path(out) if out is not None else Path(cfg.results) / "paper-table.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render(cfg, errors, successes, by_category, real_successes, test_successes, trained_on,
                          per_object))
    return out
