"""How much error an executor forgives: ``gt`` under controlled perturbations of the true
cross-pose, success rate against perturbation size (``wpbench sensitivity``).

Perturbations (applied to each stage's true cross-pose T, seeded by episode and stage):

- ``rotation``: T turned by ``size`` degrees about a random axis through the predicted
  goal centre of the action object.
- ``translation``: T moved ``size`` metres in a random direction.
- ``translation_wall``: T moved ``size`` metres horizontally toward the nearest furniture
  surface beside the goal (a wall of the cavity, the door frame), found from the
  furniture's true geometry: this is the evaluation harness, it may use ground truth
  to perturb it.
- ``hinge_tilt`` (articulated stages): the screw axis of T tilted by ``size`` degrees
  about a random direction perpendicular to it, same angle, slide and axis point.
- ``motion_scale`` (articulated stages): ``size`` times the true motion along its screw.

The perturbed truth is a privileged policy that lives only here (it is not registered).
Free-floating stages under ``hinge_tilt`` / ``motion_scale`` get the true cross-pose.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.spatial.transform import Rotation

from wpbench.evaluation.summary import wilson_interval
from wpbench.names import ARTICULATED
from wpbench.policies.base import Policy, PolicyConfig, PolicyOutput
from wpbench.sim.screw_path import Screw, screw_at, screw_of

PERTURBATION_SIZES: dict[str, tuple[float, ...]] = {
    "rotation": (0.0, 10.0, 20.0, 30.0, 45.0),             # deg
    "translation": (0.0, 0.05, 0.10, 0.15, 0.20),          # m
    "translation_wall": (0.0, 0.05, 0.10, 0.15, 0.20),     # m
    "hinge_tilt": (0.0, 10.0, 20.0, 30.0, 45.0),           # deg
    "motion_scale": (0.5, 0.75, 1.0, 1.25, 1.5),           # x the true motion
}
UNITS = {"rotation": "deg", "translation": "m", "translation_wall": "m", "hinge_tilt": "deg", "motion_scale": "x"}
ARTICULATED_ONLY = ("hinge_tilt", "motion_scale")
WALL_SAMPLES = 20000       # furniture surface samples searched for the nearest wall
WALL_BAND_MARGIN = 0.01    # m: a wall counts when it is beside the object's height range, this much inside it
CSV_COLUMNS = ("task", "executor", "grasp", "perturbation", "size", "unit", "episodes", "successes",
               "success_rate", "ci_low", "ci_high")


def _check_T(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"expected a (4, 4) cross-pose, got shape {T.shape}")
    return T


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        raise ValueError("direction has zero length")
    return np.asarray(v, dtype=np.float64) / n


def rotated_about(T: np.ndarray, degrees: float, axis: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(4, 4): T followed by a turn of ``degrees`` about the line through ``centre`` (3,) along ``axis`` (3,)."""
    T = _check_T(T)
    R = np.eye(4)
    R[:3, :3] = Rotation.from_rotvec(np.radians(degrees) * _unit(axis)).as_matrix()
    R[:3, 3] = np.asarray(centre) - R[:3, :3] @ np.asarray(centre)
    return R @ T


def translated(T: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(4, 4): T followed by a translation by ``offset`` (3,)."""
    out = _check_T(T).copy()
    out[:3, 3] += np.asarray(offset, dtype=np.float64)
    return out


def hinge_tilted(T: np.ndarray, degrees: float, toward: np.ndarray) -> np.ndarray:
    """(4, 4): T's screw with its axis tilted by ``degrees`` toward ``toward`` (3,; its part
    perpendicular to the axis is used), the same angle, axis point and slide. A pure
    translation's direction is tilted the same way."""
    screw = screw_of(_check_T(T))
    perp = np.asarray(toward, dtype=np.float64) - (np.asarray(toward) @ screw.axis) * screw.axis
    turn = Rotation.from_rotvec(np.radians(degrees) * _unit(np.cross(screw.axis, _unit(perp))))
    axis = turn.apply(screw.axis)
    return screw_at(Screw(screw.angle, axis, screw.point, screw.slide), 1.0)


def motion_scaled(T: np.ndarray, factor: float) -> np.ndarray:
    """(4, 4): ``factor`` times T's motion along its screw (``exp(factor log T)``)."""
    return screw_at(screw_of(_check_T(T)), float(factor))


def nearest_wall_direction(centre: np.ndarray, z_range: tuple[float, float], surface: np.ndarray) -> np.ndarray:
    """(3,) horizontal unit direction from ``centre`` (3,) to the nearest point of ``surface``
    (M, 3) whose height lies inside ``z_range`` (shrunk by WALL_BAND_MARGIN): the wall or
    frame the object would be pushed into. ValueError when no surface point is beside it."""
    lo, hi = z_range[0] + WALL_BAND_MARGIN, z_range[1] - WALL_BAND_MARGIN
    s = np.asarray(surface, dtype=np.float64)
    beside = s[(s[:, 2] >= min(lo, hi)) & (s[:, 2] <= max(lo, hi))]
    if len(beside) == 0:
        raise ValueError("no furniture surface beside the goal height")
    flat = beside[:, :2] - np.asarray(centre)[:2]
    k = int(np.argmin(np.linalg.norm(flat, axis=1)))
    return np.array([*_unit(flat[k]), 0.0])


def perturb(kind: str, size: float, T: np.ndarray, stage_kind: str, action_points: np.ndarray,
            rng: np.random.Generator, wall_surface: Callable[[], np.ndarray]) -> np.ndarray:
    """The cross-pose T (4, 4) perturbed by ``kind`` of ``size``; ``action_points`` (N, 3)
    is the stage's observed action cloud (its goal centre is the turning point and the
    start of the wall search); ``wall_surface()`` gives furniture surface samples (M, 3)."""
    if kind not in PERTURBATION_SIZES:
        raise ValueError(f"unknown perturbation {kind!r}; valid: {', '.join(PERTURBATION_SIZES)}")
    goal = np.asarray(action_points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    direction = rng.normal(size=3)
    if kind == "rotation":
        return rotated_about(T, size, direction, goal.mean(0))
    if kind == "translation":
        return translated(T, size * _unit(direction))
    if kind == "translation_wall":
        toward = nearest_wall_direction(goal.mean(0), (float(goal[:, 2].min()), float(goal[:, 2].max())), wall_surface())
        return translated(T, size * toward)
    if stage_kind != ARTICULATED:
        return T
    if kind == "hinge_tilt":
        return hinge_tilted(T, size, direction)
    return motion_scaled(T, size)


@dataclass
class PerturbedTruthConfig(PolicyConfig):
    name = "gt-perturbed"
    perturbation: str = "rotation"
    size: float = 0.0


class PerturbedTruth(Policy):
    """The true cross-pose, perturbed (privileged; used only by this harness). ``env`` is the
    unwrapped task env, read for the furniture surface when the perturbation needs a wall."""

    uses_ground_truth = True

    def __init__(self, config: PerturbedTruthConfig, env):
        self.config = config
        self.env = env
        self.seed = 0

    def wall_surface(self) -> np.ndarray:
        from wpbench.sim.observation import sample_mesh_surface

        f = self.env.furniture
        return sample_mesh_surface(f.world_mesh(f.links), WALL_SAMPLES, np.random.default_rng(self.seed))

    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        if info is None:
            raise ValueError("the perturbed truth needs the env's ground truth as info")
        T = np.asarray(info["cross_pose"], dtype=np.float64)
        rng = np.random.default_rng([self.seed, int(info["stage"]), 23])
        out = perturb(self.config.perturbation, self.config.size, T, info["kind"], obs["action_points"], rng,
                      self.wall_surface)
        return PolicyOutput(out)


@dataclass
class Point:
    task: str
    executor: str
    grasp: str
    perturbation: str
    size: float
    episodes: int
    successes: int

    def row(self) -> dict[str, Any]:
        lo, hi = wilson_interval(self.successes, self.episodes)
        return {"task": self.task, "executor": self.executor, "grasp": self.grasp, "perturbation": self.perturbation,
                "size": self.size, "unit": UNITS[self.perturbation], "episodes": self.episodes,
                "successes": self.successes, "success_rate": self.successes / max(self.episodes, 1),
                "ci_low": lo, "ci_high": hi}


def perturbations_for(stages: tuple[str, ...]) -> tuple[str, ...]:
    """The perturbations that apply to a task with these stage kinds."""
    has_joint = ARTICULATED in stages
    return tuple(k for k in PERTURBATION_SIZES if has_joint or k not in ARTICULATED_ONLY)


def run_sensitivity(task: str, executor: str, grasp: str, episodes: int, obs_mode: str = "mesh", split: str = "val",
                    perturbations: tuple[str, ...] | None = None, first_seed: int = 0,
                    on_point: Callable[[Point], None] | None = None) -> list[Point]:
    """``gt`` under every perturbation and size, ``episodes`` seeds each (the same seeds at
    every point). Returns one :class:`Point` per (perturbation, size)."""
    import gymnasium as gym

    from wpbench.evaluation.runner import run_episode
    from wpbench.names import import_task

    if episodes < 1:
        raise ValueError(f"--episodes must be at least 1, got {episodes}")
    info = import_task(task)
    kinds = perturbations or perturbations_for(info.stages)
    unknown = [k for k in kinds if k not in PERTURBATION_SIZES]
    if unknown:
        raise ValueError(f"unknown perturbation(s) {unknown}; valid: {', '.join(PERTURBATION_SIZES)}")
    kwargs = {"executor": executor}
    if executor == "gripper":
        kwargs["grasp"] = grasp
    env = gym.make(info.env_id, obs_mode=obs_mode, assets="procedural", split=split, **kwargs)
    points = []
    try:
        for kind in kinds:
            for size in PERTURBATION_SIZES[kind]:
                policy = PerturbedTruth(PerturbedTruthConfig(perturbation=kind, size=size), env.unwrapped)
                wins = 0
                for seed in range(first_seed, first_seed + episodes):
                    policy.seed = seed
                    record = run_episode(env, policy, seed)
                    wins += bool(record["success"])
                point = Point(task, executor, grasp if executor == "gripper" else "", kind, float(size), episodes, wins)
                points.append(point)
                if on_point is not None:
                    on_point(point)
    finally:
        env.close()
    return points


def write_csv(points: list[Point], path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=CSV_COLUMNS)
        w.writeheader()
        for p in points:
            w.writerow(p.row())
    return path


def read_csv(path: Path) -> list[dict[str, Any]]:
    with open(path, encoding="utf-8") as f:
        return list(csv.DictReader(f))


def plot_curves(rows: list[dict[str, Any]], path: Path, title: str = "") -> Path:
    """One panel per perturbation: success rate against size with 95% Wilson intervals, one
    line per executor (+ grasp) found in ``rows`` (CSV rows, strings or numbers)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = [k for k in PERTURBATION_SIZES if any(r["perturbation"] == k for r in rows)]
    fig, axes = plt.subplots(1, len(kinds), figsize=(3.4 * len(kinds), 3.2), squeeze=False)
    for ax, kind in zip(axes[0], kinds):
        series: dict[str, list] = {}
        for r in rows:
            if r["perturbation"] == kind:
                label = r["executor"] + (f" ({r['grasp']})" if r.get("grasp") else "")
                series.setdefault(label, []).append(r)
        for label, rs in sorted(series.items()):
            rs = sorted(rs, key=lambda r: float(r["size"]))
            x = np.array([float(r["size"]) for r in rs]) * (100 if UNITS[kind] == "m" else 1)
            y = np.array([float(r["success_rate"]) for r in rs])
            lo = np.array([float(r["ci_low"]) for r in rs])
            hi = np.array([float(r["ci_high"]) for r in rs])
            ax.errorbar(x, 100 * y, yerr=100 * np.stack([y - lo, hi - y]), marker="o", capsize=3, label=label)
        unit = "cm" if UNITS[kind] == "m" else UNITS[kind]
        ax.set_xlabel(f"{kind.replace('_', ' ')} ({unit})")
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("gt success (%)")
    axes[0][-1].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
