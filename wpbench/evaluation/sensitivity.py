"""How much error an executor forgives: ``gt`` under controlled perturbations of the true
cross-pose, success rate against perturbation size (``wpbench sensitivity``).

Perturbations (applied to each stage's true cross-pose T, seeded by episode and stage):

- ``rotation``: T turned by ``size`` degrees about a random axis through the predicted
  goal centre of the action object.
- ``translation``: T moved ``size`` metres in a random direction.
- ``translation_wall``: T moved ``size`` metres horizontally toward the nearest wall beside
  the goal (a wall of the cavity, the door frame): of 72 horizontal directions, the one
  along which the goal cloud (its points within its height band, so not the floor under
  it) meets the furniture's collision mesh soonest, by ray casts. The furniture's true
  geometry is used: this is the evaluation harness, it may use ground truth to perturb
  it. A size smaller than the gap leaves the goal in the free space before the wall.
- ``into_wall`` (free-floating stages): T moved along the same direction by that gap plus
  ``size`` metres: the goal touches the wall at 0 and reaches ``size`` metres past the
  wall's face (through it, when the wall is thinner than that). A door's goal has no
  resting contact to measure from (its nearest wall may be half a metre away), so
  articulated stages keep their truth.
- ``hinge_tilt`` (articulated stages): the screw axis of T tilted by ``size`` degrees
  about a random direction perpendicular to it, same angle, slide and axis point.
- ``motion_scale`` (articulated stages): ``size`` times the true motion along its screw.

The furniture searched for walls is every link in its current pose, except the moving link
itself in an articulated stage (the door's present pose is no obstacle to its goal).

Two-stage tasks (open-then-place): each stage's truth gets the same kind and size, with
its own random direction; ``hinge_tilt`` / ``motion_scale`` perturb only the door stage
and ``into_wall`` only the place stage, the other stage keeping its true cross-pose. A point's success is the task's (both stages);
``stage_successes`` in the CSV counts each stage's own success.

The perturbed truth is a privileged policy that lives only here (it is not registered).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.spatial.transform import Rotation

from wpbench.evaluation.summary import wilson_interval
from wpbench.names import ARTICULATED, FREE
from wpbench.policies.base import Policy, PolicyConfig, PolicyOutput
from wpbench.sim.screw_path import Screw, screw_at, screw_of

PERTURBATION_SIZES: dict[str, tuple[float, ...]] = {
    "rotation": (0.0, 10.0, 20.0, 30.0, 45.0),             # deg
    "translation": (0.0, 0.05, 0.10, 0.15, 0.20),          # m
    "translation_wall": (0.0, 0.05, 0.10, 0.15, 0.20),     # m
    "into_wall": (0.0, 0.05, 0.10, 0.15, 0.20),            # m beyond touching the wall
    "hinge_tilt": (0.0, 10.0, 20.0, 30.0, 45.0),           # deg
    "motion_scale": (0.5, 0.75, 1.0, 1.25, 1.5),           # x the true motion
}
UNITS = {"rotation": "deg", "translation": "m", "translation_wall": "m", "into_wall": "m", "hinge_tilt": "deg",
         "motion_scale": "x"}
LABELS = {"rotation": "rotation about a random axis (deg)", "translation": "translation, random direction (cm)",
          "translation_wall": "translation toward the nearest wall (cm)",
          "into_wall": "goal overlapping the nearest wall (cm)", "hinge_tilt": "hinge axis tilt (deg)",
          "motion_scale": "motion scale (x true)"}
ARTICULATED_ONLY = ("hinge_tilt", "motion_scale")
FREE_ONLY = ("into_wall",)
WALL_DIRECTIONS = 72       # horizontal directions (every 5 deg) searched for the nearest wall
WALL_BAND_MARGIN = 0.01    # m: a wall counts when it is beside the object's height range, this much inside it
CSV_COLUMNS = ("task", "executor", "grasp", "perturbation", "size", "unit", "episodes", "successes",
               "success_rate", "ci_low", "ci_high", "stage_successes", "errors")
EXECUTOR_ORDER = ("ideal", "gripper", "panda")   # line order in the side-by-side figure


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


def _band(goal: np.ndarray) -> np.ndarray:
    """The points of ``goal`` (N, 3) within its height range shrunk by WALL_BAND_MARGIN (all
    of them when the cloud is flatter than that): the ones that meet a wall beside it,
    not the floor under it or a shelf above."""
    pts = np.asarray(goal, dtype=np.float64)
    lo, hi = pts[:, 2].min() + WALL_BAND_MARGIN, pts[:, 2].max() - WALL_BAND_MARGIN
    band = pts[(pts[:, 2] >= lo) & (pts[:, 2] <= hi)]
    return band if len(band) else pts


def wall_gap(goal: np.ndarray, direction: np.ndarray, mesh) -> float:
    """How far the cloud ``goal`` (N, 3) can move along ``direction`` (3,) before one of its
    band points (:func:`_band`) meets ``mesh`` (a trimesh.Trimesh): the smallest ray hit
    distance; inf when no ray meets the mesh."""
    band = _band(goal)
    u = _unit(direction)
    hits, rays, _ = mesh.ray.intersects_location(band, np.repeat(u[None], len(band), 0), multiple_hits=False)
    return float(np.min((hits - band[rays]) @ u)) if len(rays) else float("inf")


def nearest_wall(goal: np.ndarray, mesh, directions: int = WALL_DIRECTIONS) -> tuple[np.ndarray, float]:
    """``(direction (3,), gap)``: of ``directions`` horizontal directions, the one along which
    the cloud ``goal`` (N, 3) meets ``mesh`` soonest (for a flat wall, its inward normal),
    and :func:`wall_gap` along it. ValueError when no direction meets the furniture."""
    band = _band(goal)
    angles = 2 * np.pi * np.arange(directions) / directions
    dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros(directions)], 1)
    origins = np.tile(band, (directions, 1))
    rays_dir = np.repeat(dirs, len(band), 0)
    hits, rays, _ = mesh.ray.intersects_location(origins, rays_dir, multiple_hits=False)
    if len(rays) == 0:
        raise ValueError("no furniture surface beside the goal in any horizontal direction")
    dist = np.einsum("ij,ij->i", hits - origins[rays], rays_dir[rays])
    gaps = np.full(directions, np.inf)
    np.minimum.at(gaps, rays // len(band), dist)
    k = int(np.argmin(gaps))
    return dirs[k], float(gaps[k])


def perturb(kind: str, size: float, T: np.ndarray, stage_kind: str, action_points: np.ndarray,
            rng: np.random.Generator, wall_mesh: Callable[[], Any]) -> np.ndarray:
    """The cross-pose T (4, 4) perturbed by ``kind`` of ``size``; ``action_points`` (N, 3)
    is the stage's observed action cloud (its goal is the cloud moved by T: the goal's
    centre is the turning point, the goal cloud is what meets a wall); ``wall_mesh()``
    gives the furniture's collision mesh (trimesh.Trimesh) for the wall perturbations."""
    if kind not in PERTURBATION_SIZES:
        raise ValueError(f"unknown perturbation {kind!r}; valid: {', '.join(PERTURBATION_SIZES)}")
    goal = np.asarray(action_points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    direction = rng.normal(size=3)
    if kind == "rotation":
        return rotated_about(T, size, direction, goal.mean(0))
    if kind == "translation":
        return translated(T, size * _unit(direction))
    if (kind in ARTICULATED_ONLY and stage_kind != ARTICULATED) or (kind in FREE_ONLY and stage_kind == ARTICULATED):
        return T
    if kind in ("translation_wall", "into_wall"):
        toward, gap = nearest_wall(goal, wall_mesh())
        return translated(T, (size + (gap if kind == "into_wall" else 0.0)) * toward)
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

    def wall_mesh(self):
        """The furniture in its current pose, without the moving link in an articulated stage."""
        f = self.env.furniture
        links = f.anchor_links() if self.env.stage_kind == ARTICULATED else f.links
        return f.world_mesh(links)

    def predict(self, obs: dict[str, Any], info: dict[str, Any] | None = None) -> PolicyOutput:
        if info is None:
            raise ValueError("the perturbed truth needs the env's ground truth as info")
        T = np.asarray(info["cross_pose"], dtype=np.float64)
        rng = np.random.default_rng([self.seed, int(info["stage"]), 23])
        out = perturb(self.config.perturbation, self.config.size, T, info["kind"], obs["action_points"], rng,
                      self.wall_mesh)
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
    stage_successes: tuple[int, ...] = ()   # each stage's own successes, in stage order
    errors: int = 0                         # episodes the simulator failed (counted as failures)

    def row(self) -> dict[str, Any]:
        lo, hi = wilson_interval(self.successes, self.episodes)
        return {"task": self.task, "executor": self.executor, "grasp": self.grasp, "perturbation": self.perturbation,
                "size": self.size, "unit": UNITS[self.perturbation], "episodes": self.episodes,
                "successes": self.successes, "success_rate": self.successes / max(self.episodes, 1),
                "ci_low": lo, "ci_high": hi, "stage_successes": ";".join(map(str, self.stage_successes)),
                "errors": self.errors}


def perturbations_for(stages: tuple[str, ...]) -> tuple[str, ...]:
    """The perturbations that apply to a task with these stage kinds."""
    return tuple(k for k in PERTURBATION_SIZES
                 if (ARTICULATED in stages or k not in ARTICULATED_ONLY) and (FREE in stages or k not in FREE_ONLY))


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

    def make():
        return gym.make(info.env_id, obs_mode=obs_mode, assets="procedural", split=split, **kwargs)

    env = make()
    points = []
    try:
        for kind in kinds:
            for size in PERTURBATION_SIZES[kind]:
                config = PerturbedTruthConfig(perturbation=kind, size=size)
                wins, errors, stage_wins = 0, 0, [0] * len(info.stages)
                for seed in range(first_seed, first_seed + episodes):
                    policy = PerturbedTruth(config, env.unwrapped)
                    policy.seed = seed
                    try:
                        record = run_episode(env, policy, seed)
                    except Exception:  # noqa: BLE001 - a simulator error fails this episode; a fresh env runs the next
                        errors += 1
                        env.close()
                        env = make()
                        continue
                    wins += bool(record["success"])
                    for i, stage in enumerate(record["stages"]):
                        stage_wins[i] += bool(stage["success"])
                point = Point(task, executor, grasp if executor == "gripper" else "", kind, float(size), episodes, wins,
                              tuple(stage_wins), errors)
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


def _series_key(label: str) -> tuple[int, str]:
    name = label.split(" ")[0]
    return (EXECUTOR_ORDER.index(name) if name in EXECUTOR_ORDER else len(EXECUTOR_ORDER), label)


def plot_curves(rows: list[dict[str, Any]], path: Path, title: str = "", columns: int = 3) -> Path:
    """One panel per perturbation (``columns`` to a row): success rate against size with 95%
    Wilson bands, one line per executor (+ grasp) found in ``rows`` (CSV rows, strings or
    numbers), ideal, gripper, panda first."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = [k for k in PERTURBATION_SIZES if any(r["perturbation"] == k for r in rows)]
    if not kinds:
        raise ValueError("no sensitivity rows to plot")
    ncol = min(columns, len(kinds))
    nrow = -(-len(kinds) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol, 3.1 * nrow), squeeze=False)
    for ax in axes.flat[len(kinds):]:
        ax.set_visible(False)
    for ax, kind in zip(axes.flat, kinds):
        series: dict[str, list] = {}
        for r in rows:
            if r["perturbation"] == kind:
                label = r["executor"] + (f" ({r['grasp']})" if r.get("grasp") else "")
                series.setdefault(label, []).append(r)
        for label in sorted(series, key=_series_key):
            rs = sorted(series[label], key=lambda r: float(r["size"]))
            x = np.array([float(r["size"]) for r in rs]) * (100 if UNITS[kind] == "m" else 1)
            y = 100 * np.array([float(r["success_rate"]) for r in rs])
            lo = 100 * np.array([float(r["ci_low"]) for r in rs])
            hi = 100 * np.array([float(r["ci_high"]) for r in rs])
            (line,) = ax.plot(x, y, marker="o", label=label)
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.15, linewidth=0)
        ax.set_xlabel(LABELS[kind], fontsize=9)
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
    for row in axes:
        row[0].set_ylabel("gt success (%)")
    axes.flat[len(kinds) - 1].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_task(folder: Path, task: str) -> Path:
    """Draw ``<folder>/<task>.png`` from every ``<folder>/<task>_<executor>[_<grasp>].csv``
    there: one panel per perturbation, one line per executor with its 95% band."""
    folder = Path(folder)
    files = sorted(folder.glob(f"{task}_*.csv"))
    rows = [r for f in files for r in read_csv(f) if r["task"] == task]
    if not rows:
        raise ValueError(f"no {task}_*.csv in {folder}; run wpbench sensitivity --task {task} first")
    n = sorted({r["episodes"] for r in rows})
    return plot_curves(rows, folder / f"{task}.png",
                       title=f"{task}: gt with a perturbed cross-pose ({', '.join(n)} episodes per point, 95% bands)")
