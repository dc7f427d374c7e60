"""Rerun recordings of benchmark runs (``wpbench run ... --record FILE.rrd``).

``RerunRecorder`` is an *observer* of ``wpbench.evaluation.runner.run_episode``:
the runner calls ``begin_episode`` after each reset, ``log_prediction`` before
each stage is executed, ``log_stage_result`` after it, ``end_episode`` with the
episode record, and the CLI calls ``close()`` at the end. Everything goes into
ONE ``.rrd`` file (no viewer is spawned, nothing leaves the machine); open it
with ``rerun FILE.rrd``.

Time lines (all monotonic over the whole run, so episodes follow one another):
    ``episode``  (sequence) the recorder's episode counter, 0, 1, ...;
    ``sim_step`` (sequence) physics steps since the run started;
    ``sim_time`` (duration) ``sim_step`` / the env's physics frequency.

Entities (``<link>`` is the URDF link name):
    ``world/furniture/<link>``  Mesh3D of the link's collision geometry in the link
                               frame (once per episode) + Transform3D (link -> world),
                               refreshed every ``physics_stride`` physics steps;
    ``world/object``           the free object's mesh (object frame) + its pose;
    ``world/observation/action``, ``world/observation/anchor``   the two clouds;
    ``world/prediction/goal``  action points moved by the predicted cross-pose;
    ``world/truth/goal``       action points moved by the true cross-pose;
    ``world/truth/in_region``  Boxes3D: where a placed object must come to rest;
    ``world/prediction/flow``  Arrows3D from the action points (diagnostic ``flow``);
    ``world/prediction/correspondences``  Arrows3D action point -> ``action_targets``;
    ``world/prediction/anchor_correspondences``  Arrows3D ``anchor_sources`` -> anchor point;
    ``world/prediction/goal_taxpose``, ``.../goal_goalflow``  each branch's goal alone;
    ``metrics/prediction/w``   mean of the diagnostic ``w`` per stage (Scalars);
    ``metrics/<kind>/<name>``  each stage's metrics (Scalars; success as 0/1);
    ``metrics/episode/<name>`` each episode's metrics (Scalars);
    ``sim/target_joint``, ``sim/object_height``  joint value and object height (Scalars);
    ``world/robot/<link>``     ``gripper`` / ``panda`` runs: the floating hand's or the arm's
                               links, each a Mesh3D of its URDF visuals in the link frame
                               (once per run) + Transform3D (link -> world) every
                               ``physics_stride`` physics steps while the robot works;
    ``world/robot``            Transform3D scale: 1 while the robot works, ``HIDDEN_SCALE``
                               while it waits at its parking place far from the scene
                               (between stages), so it vanishes instead of pulling the view away;
    ``world/executor/grasp_point``     Points3D: the stage's grasp (the TCP at contact);
    ``world/executor/grasp_approach``  Arrows3D: the approach, ending at the grasp point;
    ``world/executor/planned_path``    LineStrips3D: the TCP path the executor planned
                               (the screw for a door or drawer, the carry waypoints for an object);
    ``world/executor/executed_path``   LineStrips3D: the TCP positions the robot reached
                               during the stage (sampled with the poses);
                               the grasp and the plan are logged at the stage's start time,
                               the executed path at its end; ``ideal`` runs have none of these;
    ``episode/summary``        TextDocument (markdown) of the last episode;
    ``log``                    TextLog, one line per stage and per episode.

Cost: meshes are logged once per episode (the robot's once per run), later only poses
(a handful of Transform3D every ``physics_stride`` steps), so recording adds little to a run.
"""

from __future__ import annotations

import math
import re
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wpbench.evaluation.recording_robot import RobotView, robot_of

# Stage metrics plotted as time series (the others in a stage result are strings,
# matrices or executor details that the summary text shows instead).
STAGE_SCALARS = ("rot_err_deg", "trans_err_m", "trans_err_raw_m", "point_err_m", "point_mse",
                 "open_distance", "q_final", "sim_seconds", "exec_seconds")
EPISODE_SCALARS = ("rot_err_deg", "trans_err_m", "point_err_m")
HIDDEN_SCALE = 1e-6   # the robot's scale while it is parked: too small to see, never singular

RGB = tuple[int, int, int]


@dataclass
class RecorderConfig:
    """What to record and how it looks."""

    physics_stride: int = 10              # log poses every this many physics steps
    point_radius: float = 0.004           # m, observation and goal points
    arrow_radius: float = 0.0015          # m, flow and correspondence arrows
    action_color: RGB = (230, 90, 40)     # orange
    anchor_color: RGB = (60, 130, 220)    # blue
    prediction_color: RGB = (220, 40, 200)  # magenta
    truth_color: RGB = (40, 190, 80)      # green
    furniture_color: RGB = (170, 170, 160)
    target_link_color: RGB = (200, 160, 90)  # the door / drawer
    low_weight_color: RGB = (90, 90, 90)     # correspondence arrows blend from this (weight 0)
    high_weight_color: RGB = (250, 220, 30)  # ... to this (the largest weight)
    grasp_color: RGB = (250, 200, 30)         # grasp point and approach
    planned_path_color: RGB = (220, 40, 200)  # the executor's plan follows the prediction: magenta
    executed_path_color: RGB = (30, 200, 220)  # cyan
    path_radius: float = 0.002               # m, planned and executed TCP paths
    approach_length: float = 0.1             # m, the approach arrow

    def __post_init__(self) -> None:
        if int(self.physics_stride) < 1:
            raise ValueError(
                f"physics_stride must be >= 1 (log poses every k physics steps), got {self.physics_stride}")


class RerunRecorder:
    """Writes a run to one ``.rrd`` file; an observer for ``run_benchmark(..., observer=...)``.

    ``path``: the ``.rrd`` file to write (its folder is created, an existing file replaced).
    ``application``: the rerun application id shown in the viewer.
    """

    def __init__(self, path: str | Path, application: str = "wpbench", config: RecorderConfig | None = None):
        import rerun as rr

        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise ValueError(f"a rerun recording must be a .rrd file, got {str(path)!r}; e.g. --record run.rrd")
        self.config = config or RecorderConfig()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._rr = rr
        self._stream = rr.RecordingStream(application, recording_id=uuid.uuid4(), default_enabled=True)
        if not self._stream.is_enabled():
            raise ValueError("rerun logging is disabled in this environment (RERUN=off?); unset RERUN to record")
        self._stream.save(self.path)
        self._stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._episode = -1            # index of the episode being recorded
        self._step_offset = 0         # run-wide physics steps before the current episode
        self._sim_freq = 1.0
        self._hooked_env = None
        self._previous_hook = None
        self._last_pose_step = -1
        self._poses = _PoseBuffer()
        self._link_paths: dict[str, str] = {}
        self._robot: RobotView | None = None
        self._robot_logged: str | None = None   # the robot kind whose meshes are in the recording
        self._robot_shown: bool | None = None  # last logged state of ``world/robot``'s scale
        self._tcp_track: list[np.ndarray] = []  # TCP positions sampled during the current stage
        self._stage_start = 0                   # run-wide physics step at which the current stage began
        self._closed = False

    # ------------------------------------------------------------------ observer API
    def begin_episode(self, env, seed: int) -> None:
        """After ``env.reset``: clear the last episode's scene, log this one's meshes and start pose."""
        rr = self._rr
        self._check_open()
        self._detach()
        self._episode += 1
        self._sim_freq = float(getattr(env, "sim_freq", 0) or 1.0)
        self._set_time(env)
        self._stream.log("world/furniture", rr.Clear(recursive=True))
        self._stream.log("world/object", rr.Clear(recursive=True))
        self._stream.log("world/observation", rr.Clear(recursive=True))
        self._stream.log("world/prediction", rr.Clear(recursive=True))
        self._stream.log("world/truth", rr.Clear(recursive=True))
        self._log_furniture_meshes(env)
        self._log_object_mesh(env)
        self._log_in_region(env)
        self._begin_robot(env)
        self._sample_poses(env)
        self._flush_poses()
        asset = env.asset
        self._stream.log("log", rr.TextLog(
            f"episode {self._episode} (seed {seed}): {asset.category} {asset.object_id}"
            + (f", object {env.free_spec.name}" if getattr(env, "free_spec", None) is not None else ""),
            level=rr.TextLogLevel.INFO))
        self._attach(env)

    def log_prediction(self, env, obs: dict[str, Any], transform: np.ndarray, diagnostics: dict[str, Any]) -> None:
        """Before a stage runs: the observation, predicted and true goals, and the policy's diagnostics.

        ``obs``: ``action_points`` (NA, 3), ``anchor_points`` (NB, 3); ``transform`` (4, 4),
        possibly NaN; ``diagnostics`` may hold ``flow`` (NA, 3), ``w`` () / (NA,),
        ``action_targets`` (NA, 3), ``action_weights`` (NA,), ``anchor_sources`` (NB, 3),
        ``anchor_weights`` (NB,), ``taxpose_transform`` / ``goalflow_transform`` (4, 4),
        numpy or torch, with or without a leading batch dimension of 1.
        """
        rr, cfg = self._rr, self.config
        self._check_open()
        self._set_time(env)
        action = _points(obs["action_points"], "obs['action_points']")
        anchor = _points(obs["anchor_points"], "obs['anchor_points']")
        self._stream.log("world/prediction", rr.Clear(recursive=True))
        self._stage_start = self._step(env)
        self._tcp_track = []
        if self._robot is not None:
            self._stream.log("world/executor", rr.Clear(recursive=True))
        self._stream.log("world/observation/action",
                         rr.Points3D(action, colors=cfg.action_color, radii=cfg.point_radius))
        self._stream.log("world/observation/anchor",
                         rr.Points3D(anchor, colors=cfg.anchor_color, radii=cfg.point_radius))
        truth = np.asarray(env.ground_truth()["cross_pose"], dtype=np.float64)
        self._stream.log("world/truth/goal",
                         rr.Points3D(_apply(truth, action), colors=cfg.truth_color, radii=cfg.point_radius))
        predicted = _array(transform)
        if predicted is not None and predicted.shape == (4, 4) and np.all(np.isfinite(predicted)):
            goal = _apply(predicted, action)
            self._stream.log("world/prediction/goal",
                             rr.Points3D(goal, colors=cfg.prediction_color, radii=cfg.point_radius))
        else:
            self._warn(f"stage {env.stage_index}: no finite predicted cross-pose to show")
        self._log_diagnostics(env, action, anchor, diagnostics or {})

    def log_stage_result(self, env, result: dict[str, Any]) -> None:
        """After a stage ran: its final poses, metrics as Scalars and one log line."""
        rr = self._rr
        self._check_open()
        self._set_time(env)
        self._sample_poses(env)
        self._flush_poses()
        self._log_executor(env, result)
        kind = str(result.get("kind", env.stage_kind))
        self._stream.log(f"metrics/{kind}/success", rr.Scalars(float(bool(result.get("success")))))
        for name in STAGE_SCALARS:
            value = result.get(name)
            if isinstance(value, (int, float)) and math.isfinite(value):
                self._stream.log(f"metrics/{kind}/{name}", rr.Scalars(float(value)))
        ok = bool(result.get("success"))
        text = (f"episode {self._episode} stage {kind}: {'success' if ok else 'FAIL'}, "
                f"rot {_fmt(result.get('rot_err_deg'))} deg, trans {_fmt(result.get('trans_err_m'))} m")
        if not ok and result.get("failure_reason"):
            text += f" ({result['failure_reason']})"
        self._stream.log("log", rr.TextLog(text, level=rr.TextLogLevel.INFO if ok else rr.TextLogLevel.WARN))

    def end_episode(self, env, record: dict[str, Any]) -> None:
        """After the last stage: episode metrics and a markdown summary; stop following the sim."""
        rr = self._rr
        self._check_open()
        self._set_time(env)
        self._stream.log("metrics/episode/success", rr.Scalars(float(bool(record.get("success")))))
        for name in EPISODE_SCALARS:
            value = record.get(name)
            if isinstance(value, (int, float)) and math.isfinite(value):
                self._stream.log(f"metrics/episode/{name}", rr.Scalars(float(value)))
        self._stream.log("episode/summary", rr.TextDocument(_summary_markdown(self._episode, record),
                                                            media_type=rr.MediaType.MARKDOWN))
        ok = bool(record.get("success"))
        self._stream.log("log", rr.TextLog(
            f"episode {self._episode}: {'SUCCESS' if ok else 'failure'} ({record.get('category')} "
            f"{record.get('object_id')}, seed {record.get('seed')})",
            level=rr.TextLogLevel.INFO if ok else rr.TextLogLevel.WARN))
        self._detach()

    def close(self) -> None:
        """Flush and finish the file (safe to call twice; the file is valid even with no episode)."""
        if self._closed:
            return
        self._detach()
        self._stream.flush()
        self._stream.disconnect()
        self._closed = True

    def __enter__(self) -> RerunRecorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ simulation hook
    def _attach(self, env) -> None:
        """Follow the simulation: the env calls ``on_physics_step(env)`` after every physics step."""
        self._previous_hook = env.__dict__.get("on_physics_step")
        env.on_physics_step = self._on_physics_step
        self._hooked_env = env

    def _detach(self) -> None:
        """Send buffered poses, give the env its hook back, move the run-wide step counter past this episode."""
        self._flush_poses()
        env = self._hooked_env
        if env is None:
            return
        if self._previous_hook is None:
            env.__dict__.pop("on_physics_step", None)   # back to the class default
        else:
            env.on_physics_step = self._previous_hook
        # The next episode's steps start after this one's (+1 so the two never share a step).
        self._step_offset += int(getattr(env, "physics_steps", 0)) + 1
        self._hooked_env = self._previous_hook = None

    def _on_physics_step(self, env) -> None:
        if self._previous_hook is not None:
            self._previous_hook(env)
        if env.physics_steps % self.config.physics_stride == 0:
            self._sample_poses(env)

    # ------------------------------------------------------------------ helpers
    def _step(self, env) -> int:
        """The run-wide physics step the env is at."""
        return self._step_offset + int(getattr(env, "physics_steps", 0))

    def _set_time(self, env, step: int | None = None) -> None:
        step = self._step(env) if step is None else step
        self._stream.set_time("episode", sequence=max(self._episode, 0))
        self._stream.set_time("sim_step", sequence=step)
        self._stream.set_time("sim_time", duration=step / self._sim_freq)

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"the recording {self.path} is closed; make a new RerunRecorder to record more")

    def _warn(self, text: str) -> None:
        self._stream.log("log", self._rr.TextLog(text, level=self._rr.TextLogLevel.WARN))

    def _link_path(self, link) -> str:
        name = link.name
        if name not in self._link_paths:
            # ManiSkill names links "scene-<k>-furniture_<urdf name>"; the viewer shows the URDF name.
            short = name.split("furniture_", 1)[-1] if name.startswith("scene-") else name
            self._link_paths[name] = "world/furniture/" + (re.sub(r"[^A-Za-z0-9_\-]", "_", short) or "link")
        return self._link_paths[name]

    def _log_furniture_meshes(self, env) -> None:
        rr, cfg = self._rr, self.config
        furniture = env.furniture
        self._link_paths = {}
        for link in furniture.links:
            mesh = furniture.link_mesh(link)
            if mesh is None or len(mesh.faces) == 0:
                continue   # a link without collision shapes (e.g. the URDF base) has nothing to draw
            color = cfg.target_link_color if link is furniture.target_link else cfg.furniture_color
            self._stream.log(self._link_path(link), _mesh3d(rr, mesh, color))

    def _log_in_region(self, env) -> None:
        """The furniture's "in" box, where a placed object must come to rest (the free stage's success test)."""
        root = getattr(env, "root_pose", None)
        if root is None or not hasattr(env.furniture, "in_region_world"):
            return
        center, rotation, half = env.furniture.in_region_world(np.asarray(root, dtype=np.float64))
        rr = self._rr
        self._stream.log("world/truth/in_region", rr.Transform3D(translation=center, mat3x3=rotation),
                         rr.Boxes3D(half_sizes=[half], colors=self.config.truth_color))

    def _log_object_mesh(self, env) -> None:
        if getattr(env, "free_body", None) is None:
            return
        rgba = getattr(env.free_spec, "rgba", None)
        color = _rgb255(rgba) if rgba is not None else self.config.action_color
        self._stream.log("world/object", _mesh3d(self._rr, env.free_mesh, color))

    def _sample_poses(self, env) -> None:
        """Buffer link and object poses at the current step (once per step: the hook and a stage end may meet)."""
        step = self._step_offset + int(getattr(env, "physics_steps", 0))
        if step == self._last_pose_step:
            return
        self._last_pose_step = step
        furniture = env.furniture
        for link in furniture.links:
            self._poses.add_pose(self._link_path(link), step, link.entity_pose)
        self._poses.add_scalar("sim/target_joint", step, furniture.qpos)
        body = getattr(env, "free_body", None)
        if body is not None:
            pose = body.entity_pose
            self._poses.add_pose("world/object", step, pose)
            self._poses.add_scalar("sim/object_height", step, float(pose.p[2]))
        self._sample_robot(step)

    # ------------------------------------------------------------------ the robot (gripper, panda)
    def _begin_robot(self, env) -> None:
        """Find the env's robot; log its meshes the first time it appears in the run."""
        if self._robot_logged is not None:
            self._stream.log("world/executor", self._rr.Clear(recursive=True))
        self._robot = robot_of(env)
        self._robot_shown = None
        self._tcp_track = []
        if self._robot is None:
            if self._robot_logged is not None:   # an earlier env had one: keep it out of sight
                self._poses.add_scale("world/robot", self._step(env), HIDDEN_SCALE)
            return
        if self._robot_logged == self._robot.kind:
            return
        rr = self._rr
        self._stream.log("world/robot", rr.Clear(recursive=True))
        for name, mesh in zip(self._robot.names, self._robot.meshes):
            if mesh is not None:
                self._stream.log(f"world/robot/{name}", _colored_mesh3d(rr, mesh))
        self._robot_logged = self._robot.kind

    def _sample_robot(self, step: int) -> None:
        """The robot's link poses and TCP while it works; only its vanishing while it is parked."""
        robot = self._robot
        if robot is None:
            return
        shown = not robot.parked()
        if shown != self._robot_shown:
            self._poses.add_scale("world/robot", step, 1.0 if shown else HIDDEN_SCALE)
            self._robot_shown = shown
        if not shown:
            return
        for name, link, mesh in zip(robot.names, robot.links, robot.meshes):
            if mesh is not None:
                self._poses.add_pose(f"world/robot/{name}", step, link.entity_pose)
        self._tcp_track.append(np.asarray(robot.tcp(), dtype=np.float64)[:3, 3].copy())

    def _log_executor(self, env, result: dict[str, Any]) -> None:
        """The stage's grasp and planned TCP path (at the stage's start) and executed TCP path (now)."""
        if self._robot is None:
            return
        rr, cfg = self._rr, self.config
        grasp = _array(result.get("grasp_point"))
        approach = _array(result.get("grasp_approach"))
        planned = _array(result.get("planned_path"))
        self._set_time(env, self._stage_start)
        if grasp is not None and grasp.shape == (3,) and np.all(np.isfinite(grasp)):
            self._stream.log("world/executor/grasp_point",
                             rr.Points3D([grasp], colors=cfg.grasp_color, radii=2 * cfg.point_radius))
            if approach is not None and approach.shape == (3,) and np.linalg.norm(approach) > 1e-9:
                vector = cfg.approach_length * approach / np.linalg.norm(approach)
                self._stream.log("world/executor/grasp_approach", rr.Arrows3D(
                    origins=[grasp - vector], vectors=[vector], colors=cfg.grasp_color, radii=cfg.arrow_radius))
        if planned is not None and planned.ndim == 2 and planned.shape[1] == 3 and len(planned) >= 2:
            self._stream.log("world/executor/planned_path", rr.LineStrips3D(
                [planned], colors=cfg.planned_path_color, radii=cfg.path_radius))
        self._set_time(env)
        executed = np.asarray(self._tcp_track) if len(self._tcp_track) >= 2 else _array(result.get("executed_path"))
        if executed is not None and executed.ndim == 2 and executed.shape[1] == 3 and len(executed) >= 2:
            self._stream.log("world/executor/executed_path", rr.LineStrips3D(
                [executed], colors=cfg.executed_path_color, radii=cfg.path_radius))

    def _flush_poses(self) -> None:
        self._poses.send(self._rr, self._stream, episode=max(self._episode, 0), sim_freq=self._sim_freq)

    def _log_diagnostics(self, env, action: np.ndarray, anchor: np.ndarray, diagnostics: dict[str, Any]) -> None:
        rr, cfg = self._rr, self.config
        na, nb = len(action), len(anchor)
        flow = _per_point(diagnostics.get("flow"), na, 3)
        if flow is not None:
            self._stream.log("world/prediction/flow", rr.Arrows3D(
                origins=action, vectors=flow, colors=cfg.prediction_color, radii=cfg.arrow_radius))
        targets = _per_point(diagnostics.get("action_targets"), na, 3)
        if targets is not None:
            colors = _weight_colors(_per_point(diagnostics.get("action_weights"), na), na, cfg)
            self._stream.log("world/prediction/correspondences", rr.Arrows3D(
                origins=action, vectors=targets - action, colors=colors, radii=cfg.arrow_radius))
        sources = _per_point(diagnostics.get("anchor_sources"), nb, 3)
        if sources is not None:
            colors = _weight_colors(_per_point(diagnostics.get("anchor_weights"), nb), nb, cfg)
            self._stream.log("world/prediction/anchor_correspondences", rr.Arrows3D(
                origins=sources, vectors=anchor - sources, colors=colors, radii=cfg.arrow_radius))
        for key, entity in (("taxpose_transform", "goal_taxpose"), ("goalflow_transform", "goal_goalflow")):
            branch = _array(diagnostics.get(key))
            if branch is not None and branch.size == 16 and np.all(np.isfinite(branch)):
                self._stream.log(f"world/prediction/{entity}", rr.Points3D(
                    _apply(branch.reshape(4, 4), action), colors=cfg.prediction_color, radii=cfg.point_radius / 2))
        w = _array(diagnostics.get("w"))
        if w is not None and w.size and np.all(np.isfinite(w)):
            self._stream.log("metrics/prediction/w", rr.Scalars(float(np.mean(w))))
        missing = [k for k in ("flow", "action_targets")
                   if k in diagnostics and _per_point(diagnostics[k], na, 3) is None]
        if missing:
            self._warn(f"stage {env.stage_index}: diagnostics {missing} do not match the {na} action points; not drawn")


class _PoseBuffer:
    """Poses and scalars sampled during simulation, sent in one columnar batch per entity.

    Building one rerun archetype per sample costs about a millisecond of Python; a
    column of K samples costs about the same as one, which keeps recording cheap.
    """

    def __init__(self) -> None:
        self._poses: dict[str, tuple[list[int], list, list]] = {}
        self._scales: dict[str, tuple[list[int], list[float]]] = {}
        self._scalars: dict[str, tuple[list[int], list[float]]] = {}

    def add_pose(self, entity: str, step: int, pose) -> None:
        steps, translations, quaternions = self._poses.setdefault(entity, ([], [], []))
        steps.append(step)
        translations.append(np.asarray(pose.p, dtype=np.float32))
        quaternions.append(np.asarray(pose.q, dtype=np.float32))   # SAPIEN: w, x, y, z

    def add_scale(self, entity: str, step: int, scale: float) -> None:
        """A uniform Transform3D scale of ``entity`` from ``step`` on."""
        steps, values = self._scales.setdefault(entity, ([], []))
        steps.append(step)
        values.append(float(scale))

    def add_scalar(self, entity: str, step: int, value: float) -> None:
        steps, values = self._scalars.setdefault(entity, ([], []))
        steps.append(step)
        values.append(float(value))

    def send(self, rr, stream, episode: int, sim_freq: float) -> None:
        def times(steps: list[int]):
            steps_arr = np.asarray(steps, dtype=np.int64)
            return [rr.TimeColumn("episode", sequence=np.full(len(steps_arr), episode, dtype=np.int64)),
                    rr.TimeColumn("sim_step", sequence=steps_arr),
                    rr.TimeColumn("sim_time", duration=steps_arr / sim_freq)]

        for entity, (steps, translations, quaternions) in self._poses.items():
            wxyz = np.stack(quaternions)
            stream.send_columns(entity, indexes=times(steps), columns=rr.Transform3D.columns(
                translation=np.stack(translations), quaternion=wxyz[:, [1, 2, 3, 0]]))
        for entity, (steps, values) in self._scales.items():
            stream.send_columns(entity, indexes=times(steps), columns=rr.Transform3D.columns(
                scale=np.repeat(np.asarray(values, dtype=np.float32)[:, None], 3, axis=1)))
        for entity, (steps, values) in self._scalars.items():
            stream.send_columns(entity, indexes=times(steps), columns=rr.Scalars.columns(scalars=values))
        self._poses.clear()
        self._scales.clear()
        self._scalars.clear()


# ---------------------------------------------------------------------- conversions
def _array(value) -> np.ndarray | None:
    """numpy / torch / list -> float64 numpy (None stays None)."""
    if value is None:
        return None
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value, dtype=np.float64)


def _points(value, name: str) -> np.ndarray:
    arr = _array(value)
    if arr is None or arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be an (N, 3) array of points, got {None if arr is None else arr.shape}")
    return arr


def _per_point(value, n: int, dim: int | None = None) -> np.ndarray | None:
    """A per-point diagnostic as (n, dim) or (n,), dropping a batch dimension of 1; None if it does not fit."""
    arr = _array(value)
    if arr is None:
        return None
    want = (n, dim) if dim is not None else (n,)
    if arr.shape == (1, *want):
        arr = arr[0]
    return arr if arr.shape == want and np.all(np.isfinite(arr)) else None


def _apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(4, 4) @ (N, 3) points -> (N, 3)."""
    return points @ T[:3, :3].T + T[:3, 3]


def _rgb255(rgba) -> RGB:
    c = np.asarray(rgba, dtype=np.float64).reshape(-1)[:3]
    if c.max(initial=0.0) <= 1.0:
        c = c * 255.0
    return tuple(int(v) for v in np.clip(np.round(c), 0, 255))


def _weight_colors(weights: np.ndarray | None, n: int, cfg: RecorderConfig) -> np.ndarray:
    """(n, 3) uint8: each arrow blends from ``low_weight_color`` to ``high_weight_color`` by its weight."""
    low, high = np.asarray(cfg.low_weight_color, float), np.asarray(cfg.high_weight_color, float)
    if weights is None:
        return np.tile(high.astype(np.uint8), (n, 1))
    span = weights.max() - weights.min()
    t = (weights - weights.min()) / span if span > 0 else np.ones(n)
    return (low + t[:, None] * (high - low)).astype(np.uint8)


def _mesh3d(rr, mesh, color: RGB):
    return rr.Mesh3D(
        vertex_positions=np.asarray(mesh.vertices, dtype=np.float32),
        triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
        vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32),
        albedo_factor=[c / 255.0 for c in color] + [1.0],
    )


def _colored_mesh3d(rr, mesh):
    """A mesh with per-vertex colours (trimesh ColorVisuals) as Mesh3D."""
    return rr.Mesh3D(
        vertex_positions=np.asarray(mesh.vertices, dtype=np.float32),
        triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
        vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32),
        vertex_colors=np.asarray(mesh.visual.vertex_colors, dtype=np.uint8),
    )


def _fmt(value) -> str:
    return f"{value:.3g}" if isinstance(value, (int, float)) and math.isfinite(value) else "nan"


def _summary_markdown(episode: int, record: dict[str, Any]) -> str:
    lines = [
        f"# Episode {episode}: {'SUCCESS' if record.get('success') else 'failure'}",
        "",
        f"- furniture: {record.get('category')} `{record.get('object_id')}` ({record.get('asset_source')})",
        f"- seed: {record.get('seed')}",
    ]
    if record.get("object"):
        lines.append(f"- object: {record['object']}")
    lines += ["", "| stage | success | rot err (deg) | trans err (m) | point err (m) | reason |",
              "|---|---|---|---|---|---|"]
    for stage in record.get("stages", []):
        lines.append(f"| {stage.get('kind')} | {bool(stage.get('success'))} | {_fmt(stage.get('rot_err_deg'))} | "
                     f"{_fmt(stage.get('trans_err_m'))} | {_fmt(stage.get('point_err_m'))} | "
                     f"{stage.get('failure_reason') or ''} |")
    timings = record.get("timings", {})
    if timings:
        lines += ["", "timings: " + ", ".join(f"{k} {_fmt(v)}" for k, v in timings.items())]
    return "\n".join(lines)
