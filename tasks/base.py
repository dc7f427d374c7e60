"""The machinery every wpbench task shares: a ManiSkill3 ``BaseEnv`` whose
episode is a short list of *stages*, each one observation -> one cross-pose.

A stage is ``"articulated"`` (the action object is the furniture's door or
drawer, the goal its fully open state) or ``"free-floating"`` (the action object
is a Ravens object, the goal resting inside the furniture's cavity). A task file
only says which stages it has, how its episodes start, and documents itself;
this class loads the scene, makes observations, applies the policy's
cross-pose with the scripted executor (``env.step(T)``) and scores it.

Observation (``obs_mode``):
    ``"camera"`` (default): point clouds from a SAPIEN depth + segmentation camera
    at a random viewpoint in front of the furniture (``camera_noise=``: depth noise, holes
    and segmentation errors of a real sensor, ``wpbench.sim.camera_noise``; clean by
    default); ``"mesh"``: surface samples of the collision geometry that are visible from
    that same viewpoint (no renderer needed).
    ``obs = {"action_points": (1, NA, 3), "anchor_points": (1, NB, 3)}`` (batched torch,
    as every ManiSkill env; wrap with ``CPUGymWrapper`` for numpy): the segmented clouds,
    what a robot's camera and segmenter would give. Nothing in it says which kind of goal
    the stage has.
Action: the cross-pose, a (4, 4) matrix ``T`` with ``p_goal = T p_now`` (world frame).
Info: ``success``, ``stages_done``, and after a step ``stage_result`` (metrics and the
executor's report).
Ground truth: :meth:`CrossPoseEnv.ground_truth`, the one channel through which the true
cross-pose and kind of the current stage leave the env (only privileged policies get it).
``reset(options=...)`` keys: ``"reconfigure"`` (ManiSkill's: load a new furniture
instance), ``"restart_rng"`` (draw the furniture from the episode seed alone even after
an interrupted reset: a draw of its own, not the one ``reset(seed=s)`` gives, which on a
fresh or a used env alike is already a function of the seed), ``"start_fraction"``
(articulated stages: start the joint at this fraction of the way from closed to open
instead of the task's own draw).

Executor (``executor=``, one of ``wpbench.names.EXECUTORS``; docs/executors.md):
``"ideal"`` (default) drives the joint to the best-matching value / teleports the object;
``"gripper"`` has a floating Panda hand carry the cross-pose out; ``"panda"`` a Panda arm
(planned with mplib). Every executor
works from the stage's observed clouds and the predicted cross-pose only. Every stage
result has ``failure_reason``: "" or a code of ``wpbench.sim.failure``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils.structs.types import SimConfig

from wpbench.sim.executor import (BODY_STILL_ANG, BODY_STILL_LIN, JOINT_STILL_VEL, STILL_STEPS, ObservedMotion,
                                  execute_articulated, execute_free)
from wpbench.sim.free_object import build_free_object, raw_body
from wpbench.sim.furniture import SceneFurniture
from wpbench.sim.camera_noise import apply_camera_noise
from wpbench.sim.observation import camera_points_by_segment, fixed_size, sample_mesh_surface
from wpbench.names import ARTICULATED, EXECUTORS, FREE, OBS_MODES
from wpbench.sim import failure
from wpbench.sim.visibility import look_at_frame, visible_mask
from wpbench.sim.poses import matrix_to_pose, pose_to_matrix, project_to_rigid, transform_points, yaw_matrix

SIM_FREQ = 200
METRIC_POINTS = 512        # surface samples of the action object used for the point metrics
OPEN_TOLERANCE = 0.1       # docs/design.md: normalised distance to the open limit
AT_REST_JOINT_SPEED = 0.05        # rad/s or m/s: a joint slower than this is at rest
AT_REST_LINEAR_SPEED = 0.05       # m/s: a free object whose pose moved slower than this (and ...)
AT_REST_ANGULAR_SPEED = 0.5       # rad/s: ... turned slower than this over each of its last STILL_STEPS steps is at rest
CAMERA_FOV = 1.0           # rad, vertical
CAMERA_NOISE_STREAM = 7       # tags the camera noise's random stream apart from the episode's others
MESH_SAMPLES_PER_POINT = 4   # camera fallback: surface samples per observed point, before farthest-point sampling
VIEW_SAMPLES_PER_M2 = 20000  # mesh mode: surface samples per m^2 tested for visibility (a few per z-buffer pixel)
VIEW_RESOLUTION = 128        # mesh mode: z-buffer pixels per side
SUCCESS_CHECK_STRIDE = 10  # physics steps between checks of the success condition while simulating


RESET_OPTIONS = frozenset({"reconfigure", "env_idx", "restart_rng", "start_fraction"})


@dataclass
class StageState:
    """What a stage knew when its observation was made (kept for scoring)."""

    kind: str
    gt_cross_pose: np.ndarray          # (4, 4)
    action_surface: np.ndarray         # (METRIC_POINTS, 3) world, true geometry of the action object
    action_rotation: np.ndarray        # (3, 3) world orientation of the action object now
    q_start: float | None = None       # articulated stages: the joint value before execution


class CrossPoseEnv(BaseEnv):
    """Base class of the wpbench tasks (see the module docstring)."""

    STAGES: ClassVar[tuple[str, ...]] = ()
    SUPPORTED_OBS_MODES = ("none",)       # ManiSkill's own modes; ours are OBS_MODES
    SUPPORTED_REWARD_MODES = ("sparse", "none")
    SUPPORTED_ROBOTS = ["none"]
    on_physics_step = None  # optional hook(env) after every executor physics step (recorders use it)  # no robot: the scripted executor applies the cross-pose

    def __init__(
        self,
        *args,
        obs_mode: str = "camera",
        assets: str = "procedural",
        split: str | None = "train",
        objects: tuple[str, ...] = ("block",),
        num_action_points: int = 256,
        num_anchor_points: int = 1024,
        camera_resolution: int = 256,
        render_backend: str | None = None,
        extra_train_instances: int = 0,
        robot_uids=None,
        executor: str = "ideal",
        grasp: str = "suction",
        camera_noise: dict | None = None,
        **kwargs,
    ):
        if obs_mode not in OBS_MODES:
            raise ValueError(f"unknown obs_mode {obs_mode!r}; valid: {', '.join(OBS_MODES)}")
        from wpbench.sim.camera_noise import CameraNoise

        self.camera_noise = CameraNoise.from_settings(camera_noise)
        if obs_mode != "camera" and not self.camera_noise.is_clean:
            raise ValueError("camera noise needs obs_mode='camera' (mesh observations have no camera)")
        if executor not in EXECUTORS:
            raise ValueError(f"unknown executor {executor!r}; valid: {', '.join(EXECUTORS)}")
        from wpbench.sim.gripper_executor import GRASPS

        if grasp not in GRASPS:
            raise ValueError(f"unknown grasp {grasp!r}; valid: {', '.join(GRASPS)}")
        self.executor = executor
        self.grasp = grasp
        from wpbench.assets.library import furniture_pool_digest, load_library
        from wpbench.assets.ravens import get_ravens_object

        self.observation_source = obs_mode
        # Extra procedural training furniture (training data only; the val split is unchanged).
        extra = int(extra_train_instances) if assets == "procedural" else 0
        self.assets = load_library(assets, split=split, extra_train=extra)
        if not self.assets:
            raise ValueError(f"no furniture found for assets={assets!r} split={split!r}")
        self.furniture_pool = furniture_pool_digest(self.assets)
        self.ravens = [get_ravens_object(name) for name in objects]
        self.num_action_points = int(num_action_points)
        self.num_anchor_points = int(num_anchor_points)
        self.camera_resolution = int(camera_resolution)
        if render_backend is None:
            render_backend = "none" if obs_mode == "mesh" else "sapien_cpu"
        kwargs.setdefault("reconfiguration_freq", 1)   # a new furniture instance every episode
        kwargs.setdefault("sim_backend", "physx_cpu")
        kwargs.setdefault("reward_mode", "sparse")
        super().__init__(*args, obs_mode="none", robot_uids="none", render_backend=render_backend, **kwargs)
        self.single_action_space = gym.spaces.Box(-10.0, 10.0, shape=(4, 4), dtype=np.float32)
        self.action_space = self.single_action_space
        self._orig_single_action_space = self.single_action_space

    # ------------------------------------------------------------------ config
    @property
    def obs_mode(self) -> str:
        return self.observation_source

    @property
    def _default_sim_config(self):
        return SimConfig(sim_freq=SIM_FREQ, control_freq=SIM_FREQ)

    @property
    def _default_sensor_configs(self):
        if self.observation_source != "camera":
            return []
        # The pose is replaced in every episode by a random viewpoint (_draw_viewpoint).
        pose = sapien.Pose(p=[2.0, 0.0, 1.0])
        r = self.camera_resolution
        return [CameraConfig("view", pose=pose, width=r, height=r, fov=CAMERA_FOV, near=0.05, far=20.0, shader_pack="default")]

    @property
    def _default_human_render_camera_configs(self):
        return []

    def _load_lighting(self, options: dict):
        self.scene.set_ambient_light([0.4, 0.4, 0.4])
        self.scene.add_directional_light([1, 0.5, -1], [1, 1, 1])

    def reset(self, seed=None, options=None):
        # gymnasium's checker (and gym.Env users) expect np_random to follow the seed;
        # ManiSkill keeps its own RNGs and does not call gym.Env.reset.
        unknown = set(options or {}) - RESET_OPTIONS
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid: {sorted(RESET_OPTIONS)}")
        if (options or {}).get("restart_rng"):
            # The furniture is drawn from an rng counter that every completed reset leaves at
            # the same value (the construction's reset too); restarting it makes the scene a
            # function of the seed even after an interrupted reset, with its own draw.
            self._rng_counter = -1
        if seed is not None:
            first = seed[0] if isinstance(seed, (list, tuple)) else seed
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(int(first))
        return super().reset(seed=seed, options=options)

    def get_state_dict(self):
        # BaseEnv's version asks the (absent) robot for its controller state.
        return self.scene.get_sim_state()

    # ------------------------------------------------------------------ scene
    def _load_scene(self, options: dict):
        rng = self._episode_np_rng()
        self.asset = self.assets[int(rng.integers(len(self.assets)))]
        loader = self.scene.create_urdf_loader()
        loader.fix_root_link = True
        loader.scale = float(self.asset.scale)
        builder = loader.parse(str(self.asset.urdf))["articulation_builders"][0]
        builder.initial_pose = sapien.Pose(p=[0.0, 0.0, -self.asset.bounds_low[2]])
        self._ms_furniture = builder.build(name="furniture")
        self.furniture = SceneFurniture(self.asset, self._ms_furniture._objs[0])
        self.lift = self._floor_clearance()
        ground = self.scene.create_actor_builder()
        ground.add_box_collision(sapien.Pose(p=[0, 0, -0.05]), half_size=[20, 20, 0.05])
        ground.add_box_visual(sapien.Pose(p=[0, 0, -0.05]), half_size=[20, 20, 0.05],
                              material=sapien.render.RenderMaterial(base_color=[0.55, 0.55, 0.5, 1]))
        ground.initial_pose = sapien.Pose()
        self._ground = ground.build_static(name="ground")
        self.free_spec = None
        self.free_body = None
        if FREE in self.STAGES:
            self.free_spec = self.ravens[int(rng.integers(len(self.ravens)))]
            lo, hi = self.free_spec.scale_range
            self.free_scale = float(rng.uniform(lo, hi))
            self._ms_free = build_free_object(self.scene, self.free_spec, self.free_scale)
            self.free_body = raw_body(self._ms_free)
            self.free_mesh = self.free_spec.visual_mesh(self.free_scale)
        self.gripper = None
        if self.executor == "gripper":
            from wpbench.sim.gripper import FloatingGripper

            self.gripper = FloatingGripper(self.scene)
        self.arm = None
        if self.executor == "panda":
            from wpbench.sim.panda_arm import PandaArm

            self.arm = PandaArm(self.scene)

    def _floor_clearance(self) -> float:
        """How much to raise the furniture so its door never sweeps through the floor.

        Some real objects (PartNet-Mobility oven 101773) have a bottom hinge at floor level:
        standing on the floor, the door could not open. Raised by this much they stand as a
        wall oven is mounted. Yaw and xy do not change heights, so this is per asset.
        """
        f = self.furniture
        root = np.eye(4)
        root[2, 3] = -self.asset.bounds_low[2]
        f.articulation.set_root_pose(matrix_to_pose(root))
        link_mesh = f.link_mesh(f.target_link)
        lowest = np.inf
        for q in np.linspace(self.asset.closed_qpos, self.asset.open_qpos, 13):
            pose = f.target_link_pose_at(np.array([q]))[0]
            lowest = min(lowest, float(transform_points(pose, link_mesh.vertices)[:, 2].min()))
        return max(0.0, 0.005 - lowest)

    def _episode_np_rng(self) -> np.random.Generator:
        """numpy Generator seeded by the episode seed: same seed, same scene, same numbers."""
        return np.random.default_rng(int(self._episode_seed[0]) + 7919 * self._rng_calls())

    def _rng_calls(self) -> int:
        self._rng_counter = getattr(self, "_rng_counter", -1) + 1
        return self._rng_counter

    # ------------------------------------------------------------------ episode
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        self._rng_counter = 0
        rng = self._episode_np_rng()
        yaw = float(rng.uniform(-np.pi, np.pi))
        xy = rng.uniform(-0.3, 0.3, size=2)
        self.root_pose = yaw_matrix(yaw)
        self.root_pose[:3, 3] = [xy[0], xy[1], -self.asset.bounds_low[2] + self.lift]
        self.furniture.articulation.set_root_pose(matrix_to_pose(self.root_pose))
        self.stage_index = 0
        self.stage_results: list[dict] = []
        self.physics_steps = 0
        # The free object's motion as its pose shows it, step by step (rest is judged from it).
        self._free_motion = ObservedMotion(self.free_body, 1.0 / SIM_FREQ) if self.free_body is not None else None
        self._initialize_task(rng, options)
        # Both observation modes look from this viewpoint: the camera renders from it, the
        # mesh mode keeps the surface samples visible from it.
        self.view_eye, self.view_target = self._draw_viewpoint(rng)
        if self.observation_source == "camera":
            self._sensors["view"].camera.set_local_pose(_look_at(self.view_eye, self.view_target))
        fraction = options.get("start_fraction")
        if fraction is not None:
            if self.stage_kind != ARTICULATED:
                raise ValueError("reset option 'start_fraction' needs a task whose first stage is articulated")
            self.furniture.set_target_qpos(self.joint_fraction(float(fraction)))
        self._stage_state = self._make_stage_state()
        self._obs_cache = None

    def _initialize_task(self, rng: np.random.Generator, options: dict) -> None:
        """Set the start state (joint value, free object pose). Tasks override."""
        raise NotImplementedError

    # helpers the tasks use to set a start state
    def joint_fraction(self, fraction: float) -> float:
        """Joint value at ``fraction`` of the way from closed (0) to fully open (1)."""
        a = self.asset
        return a.closed_qpos + fraction * (a.open_qpos - a.closed_qpos)

    def place_free_object_in_front(self, rng: np.random.Generator) -> None:
        """Put the free object on the floor in front of the furniture, clear of the open door."""
        saved = self.furniture.articulation.get_qpos()
        self.furniture.set_target_qpos(self.asset.open_qpos)
        lo, hi = self.furniture.world_bounds()
        self.furniture.articulation.set_qpos(saved)
        self.furniture.drive_to(float(saved[self.furniture.target_index]))
        front = self.root_pose[:3, :3] @ np.asarray(self.asset.front, dtype=np.float64)
        front[2] = 0.0
        front /= np.linalg.norm(front)
        side = np.array([-front[1], front[0], 0.0])
        center = (lo + hi) / 2
        corners = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])])
        reach = float(np.max((corners - center[:2]) @ front[:2]))  # open furniture's extent ahead
        half = float(np.max(self.free_mesh.extents)) / 2
        distance = reach + half + rng.uniform(0.1, 0.35)
        lateral = rng.uniform(-0.3, 0.3)
        pos = center + distance * front + lateral * side
        pose = yaw_matrix(float(rng.uniform(-np.pi, np.pi)))
        pose[:3, 3] = [pos[0], pos[1], self.free_spec.rest_half_height * self.free_scale + 1e-3]
        self.free_body.entity.set_pose(matrix_to_pose(pose))
        self.free_body.set_linear_velocity(np.zeros(3))
        self.free_body.set_angular_velocity(np.zeros(3))

    def _draw_viewpoint(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(eye, target): a random viewpoint in front of the furniture that sees the furniture
        (and the free object)."""
        lo, hi = self.furniture.world_bounds()
        pts = [lo, hi]
        if self.free_body is not None and np.linalg.norm(self.free_body.entity_pose.p[:2]) < 20:
            p = np.asarray(self.free_body.entity_pose.p, dtype=np.float64)
            pts += [p - 0.1, p + 0.1]
        pts = np.array(pts)
        target = (pts.min(0) + pts.max(0)) / 2
        radius = np.linalg.norm(pts.max(0) - pts.min(0)) / 2
        front = self.root_pose[:3, :3] @ np.asarray(self.asset.front, dtype=np.float64)
        azimuth = np.arctan2(front[1], front[0]) + rng.uniform(-np.radians(35), np.radians(35))
        elevation = rng.uniform(np.radians(15), np.radians(40))
        distance = radius / np.sin(CAMERA_FOV / 2) * rng.uniform(1.0, 1.25)
        direction = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        return target + distance * direction, target

    # ------------------------------------------------------------------ stages
    @property
    def stage_kind(self) -> str:
        return self.STAGES[min(self.stage_index, len(self.STAGES) - 1)]

    def _action_surface(self, kind: str, rng: np.random.Generator) -> np.ndarray:
        if kind == ARTICULATED:
            mesh = self.furniture.world_mesh([self.furniture.target_link])
        else:
            mesh = self._free_object_mesh()
        return sample_mesh_surface(mesh, METRIC_POINTS, rng)

    def _make_stage_state(self) -> StageState:
        kind = self.stage_kind
        rng = np.random.default_rng(int(self._episode_seed[0]) * 31 + self.stage_index)
        if kind == ARTICULATED:
            now = self.furniture.target_link_pose()
            goal = self.furniture.target_link_pose_at(np.array([self.asset.open_qpos]))[0]
            return StageState(kind, goal @ np.linalg.inv(now), self._action_surface(kind, rng), now[:3, :3],
                              q_start=self.furniture.qpos)
        now = pose_to_matrix(self.free_body.entity_pose)
        return StageState(kind, self.free_goal_pose() @ np.linalg.inv(now), self._action_surface(kind, rng), now[:3, :3])

    def free_goal_pose(self) -> np.ndarray:
        """Where the free object should be: upright on the cavity floor at the centre
        of the "in" region, its axes aligned with the furniture's."""
        center, rotation, half = self.furniture.in_region_world(self.root_pose)
        up = rotation @ np.array([0.0, 0.0, 1.0])
        floor = center - half[2] * up
        goal = np.eye(4)
        goal[:3, :3] = self.root_pose[:3, :3]
        goal[:3, 3] = floor + (self.free_spec.rest_half_height * self.free_scale + 2e-3) * np.array([0, 0, 1.0])
        return goal

    # ------------------------------------------------------------------ ground truth
    def ground_truth(self) -> dict[str, Any]:
        """The current stage's truth: ``cross_pose`` (4, 4) float64 with ``p_goal = T p_now``,
        ``kind`` ("articulated" or "free-floating") and ``stage`` (its index).

        The only channel through which ground truth leaves the env: the runner hands it to
        privileged policies (``gt``, ``oracle``) and never to the others.
        """
        state = self._stage_state
        return {"cross_pose": state.gt_cross_pose.copy(), "kind": state.kind,
                "stage": min(self.stage_index, len(self.STAGES) - 1)}

    @property
    def observation_fallback(self) -> bool:
        """True when the camera saw nothing of one object and the clouds were sampled from meshes."""
        return bool(getattr(self, "_observation_fallback", False))

    def advance_physics(self) -> None:
        """One physics step of the executor's loop (the furniture held, success checked, hook called)."""
        self._physics_step()

    # ------------------------------------------------------------------ observation
    def get_obs(self, info: dict | None = None, unflattened: bool = False):
        if getattr(self, "_obs_cache", None) is None:
            self._obs_cache = self._observe()
        return self._obs_cache

    def _segment_ids(self) -> tuple[set[int], set[int]]:
        furniture_ids = {link.entity.per_scene_id for link in self.furniture.links}
        if self.stage_kind == ARTICULATED:
            action = {self.furniture.target_link.entity.per_scene_id}
            return action, furniture_ids - action
        return {self.free_body.entity.per_scene_id}, furniture_ids

    def _observe(self) -> dict[str, torch.Tensor]:
        rng = np.random.default_rng(int(self._episode_seed[0]) * 131 + self.stage_index)
        action = anchor = None
        if self.observation_source == "camera":
            action, anchor = self._camera_clouds()
        if action is None or len(action) == 0 or len(anchor) == 0:
            # Mesh mode, or a camera that saw nothing of one object (recorded in stage info):
            # then every surface sample, since the camera's view showed nothing to keep.
            self._observation_fallback = self.observation_source == "camera"
            action, anchor = self._mesh_clouds(rng, from_viewpoint=not self._observation_fallback)
        else:
            self._observation_fallback = False
        action = fixed_size(action, self.num_action_points, rng)
        anchor = fixed_size(anchor, self.num_anchor_points, rng)
        return {"action_points": torch.from_numpy(action)[None], "anchor_points": torch.from_numpy(anchor)[None]}

    def _camera_clouds(self) -> tuple[np.ndarray, np.ndarray]:
        self.scene.update_render()
        sensor = self._sensors["view"]
        sensor.capture()
        position, seg = sensor.camera.get_picture(["Position", "Segmentation"])
        cam_to_world = sensor.camera.get_model_matrix()[0].cpu().numpy().astype(np.float64)
        # Its own random stream (episode seed, stage), so a clean camera draws nothing and
        # every other random choice of the episode stays what it is without noise.
        noise_rng = np.random.default_rng([int(self._episode_seed[0]), self.stage_index, CAMERA_NOISE_STREAM])
        position, ids_image = apply_camera_noise(position[0].cpu().numpy(), seg[0, ..., 1].cpu().numpy(),
                                                 self.camera_noise, noise_rng)
        points, ids = camera_points_by_segment(position, ids_image, cam_to_world)
        action_ids, anchor_ids = self._segment_ids()
        return points[np.isin(ids, list(action_ids))], points[np.isin(ids, list(anchor_ids))]

    def _mesh_clouds(self, rng: np.random.Generator, from_viewpoint: bool) -> tuple[np.ndarray, np.ndarray]:
        """Surface samples of the action and anchor objects; with ``from_viewpoint``, only those
        a camera at the episode's viewpoint would see (the rest of the scene hides them too)."""
        if self.stage_kind == ARTICULATED:
            action_mesh = self.furniture.world_mesh([self.furniture.target_link])
            anchor_mesh = self.furniture.world_mesh(self.furniture.anchor_links())
            others = [self._free_object_mesh()] if self.free_body is not None else []
        else:
            action_mesh = self._free_object_mesh()
            anchor_mesh = self.furniture.world_mesh(self.furniture.links)
            others = []
        if not from_viewpoint:
            return (sample_mesh_surface(action_mesh, MESH_SAMPLES_PER_POINT * self.num_action_points, rng),
                    sample_mesh_surface(anchor_mesh, MESH_SAMPLES_PER_POINT * self.num_anchor_points, rng))
        meshes = [action_mesh, anchor_mesh, *others]
        clouds = [sample_mesh_surface(m, max(1, int(VIEW_SAMPLES_PER_M2 * m.area)), rng) for m in meshes]
        seen = visible_mask(np.concatenate(clouds), self.view_eye, self.view_target, CAMERA_FOV, VIEW_RESOLUTION)
        seen = np.split(seen, np.cumsum([len(c) for c in clouds])[:-1])
        action, anchor = clouds[0][seen[0]], clouds[1][seen[1]]
        # An object the viewpoint cannot see at all still gets a cloud, as a camera fallback does.
        return (action if len(action) else clouds[0]), (anchor if len(anchor) else clouds[1])

    def _free_object_mesh(self):
        return self.free_mesh.copy().apply_transform(pose_to_matrix(self.free_body.entity_pose))

    # ------------------------------------------------------------------ step
    def step(self, action):
        if self.stage_index >= len(self.STAGES):
            raise RuntimeError("episode is over: call reset() before step()")
        T = np.asarray(action.cpu().numpy() if isinstance(action, torch.Tensor) else action, dtype=np.float64)
        T = T.reshape(-1, 4, 4)[0] if T.size == 16 else T
        state = self._stage_state
        self._success_seen = False
        result = self._execute(state, T)
        metrics = self._score_stage(state, T, result)
        self.stage_results.append(metrics)
        self.stage_index += 1
        done = self.stage_index >= len(self.STAGES)
        if not done:
            self._stage_state = self._make_stage_state()
        self._obs_cache = None
        obs = self.get_obs()
        info = self.get_info()
        info["stage_result"] = metrics
        reward = info["success"].float()
        terminated = torch.tensor([done])
        self._elapsed_steps += 1
        return obs, reward, terminated, torch.tensor([False]), info

    def _physics_step(self) -> None:
        self.furniture.hold()
        motion = getattr(self, "_free_motion", None)
        if motion is not None:
            motion.observe(self.scene.px.step)
        else:
            self.scene.px.step()
        self.physics_steps += 1
        if self.physics_steps % SUCCESS_CHECK_STRIDE == 0 and self._stage_success(self._stage_state):
            self._success_seen = True
        if self.on_physics_step is not None:
            self.on_physics_step(self)

    def _execute(self, state: StageState, T: np.ndarray):
        from wpbench.sim.executor import ExecutionResult

        try:
            T = project_to_rigid(T)
        except ValueError as err:
            # An unusable prediction is the policy's failure, not the benchmark's crash.
            return ExecutionResult(ok=False, reason=failure.INVALID_PREDICTION, detail=f"invalid cross-pose: {err}")
        if self.executor == "gripper":
            return self._execute_with_gripper(state, T)
        if self.executor == "panda":
            return self._execute_with_panda(state, T)
        if state.kind == ARTICULATED:
            return execute_articulated(self.furniture, T, state.action_surface, self._physics_step, 1.0 / SIM_FREQ)
        return execute_free(self.free_body, T, self._physics_step, 1.0 / SIM_FREQ)

    def _execute_with_gripper(self, state: StageState, T: np.ndarray):
        """The floating hand, given this stage's observed action cloud and T (never the truth)."""
        from wpbench.sim.gripper_executor import Scene, execute_articulated_gripper, execute_free_gripper

        action = self.get_obs()["action_points"][0].numpy().astype(np.float64)
        if state.kind == ARTICULATED:
            f = self.furniture
            scene = Scene(self.gripper, self.scene, self.grasp, self._physics_step, 1.0 / SIM_FREQ,
                          velocities=lambda: [f.articulation.get_qvel()],
                          is_still=lambda: abs(f.qvel) < JOINT_STILL_VEL)
            return execute_articulated_gripper(scene, action, T, f.free_target_joint, f.hold_target_joint_here)
        body = self.free_body
        scene = Scene(self.gripper, self.scene, self.grasp, self._physics_step, 1.0 / SIM_FREQ,
                      velocities=lambda: [np.asarray(body.linear_velocity), np.asarray(body.angular_velocity),
                                          np.asarray(body.entity_pose.p)],
                      is_still=lambda: bool(self._free_motion.still(BODY_STILL_LIN, BODY_STILL_ANG)),
                      held_touches_furniture=self._free_object_touches_furniture)
        anchor = self.get_obs()["anchor_points"][0].numpy().astype(np.float64)
        # The robot knows where its own camera stood (the viewpoint of both observation modes).
        return execute_free_gripper(scene, action, anchor, T, viewpoint=np.asarray(self.view_eye, dtype=np.float64))

    def _execute_with_panda(self, state: StageState, T: np.ndarray):
        """The Panda arm, given this stage's observed clouds and T (never the truth)."""
        from wpbench.sim.arm_planner import ArmPlanner
        from wpbench.sim.panda_executor import ArmScene, execute_articulated_panda, execute_free_panda

        action = self.get_obs()["action_points"][0].numpy().astype(np.float64)
        anchor = self.get_obs()["anchor_points"][0].numpy().astype(np.float64)
        if state.kind == ARTICULATED:
            f = self.furniture
            scene = ArmScene(self.arm, ArmPlanner.shared(), self.scene, self.grasp, self._physics_step, 1.0 / SIM_FREQ,
                             velocities=lambda: [f.articulation.get_qvel()],
                             is_still=lambda: abs(f.qvel) < JOINT_STILL_VEL)
            return execute_articulated_panda(scene, action, anchor, T, f.free_target_joint, f.hold_target_joint_here)
        body = self.free_body
        scene = ArmScene(self.arm, ArmPlanner.shared(), self.scene, self.grasp, self._physics_step, 1.0 / SIM_FREQ,
                         velocities=lambda: [np.asarray(body.linear_velocity), np.asarray(body.angular_velocity),
                                             np.asarray(body.entity_pose.p)],
                         is_still=lambda: bool(self._free_motion.still(BODY_STILL_LIN, BODY_STILL_ANG)),
                         held_touches_furniture=self._free_object_touches_furniture)
        return execute_free_panda(scene, action, anchor, T, viewpoint=np.asarray(self.view_eye, dtype=np.float64))

    def _free_object_touches_furniture(self) -> bool:
        """The free object is pressed against the furniture (a contact with an impulse)."""
        mine = self.free_body.entity.per_scene_id
        furniture = {link.entity.per_scene_id for link in self.furniture.links}
        for c in self.scene.px.get_contacts():
            ids = {c.bodies[0].entity.per_scene_id, c.bodies[1].entity.per_scene_id}
            if mine in ids and ids & furniture and any(np.linalg.norm(p.impulse) > 1e-6 for p in c.points):
                return True
        return False

    def _score_stage(self, state: StageState, T_pred: np.ndarray, result) -> dict[str, Any]:
        from wpbench.geometry import metrics as gm

        T_gt = state.gt_cross_pose
        Tp = torch.as_tensor(np.where(np.isfinite(T_pred), T_pred, np.nan), dtype=torch.float64)[None]
        Tg = torch.as_tensor(T_gt, dtype=torch.float64)[None]
        pts = torch.as_tensor(state.action_surface, dtype=torch.float64)[None]
        symmetry = self.free_spec.symmetry if state.kind == FREE else None
        rot = gm.rotation_error_deg(Tp[:, :3, :3], Tg[:, :3, :3], symmetry=symmetry,
                                    object_rotation=torch.as_tensor(state.action_rotation)[None])
        trans = gm.translation_error(Tp, Tg, pts.mean(1))
        point_err, point_mse = gm.point_error(Tp, Tg, pts)
        success = bool(result.ok) and self._stage_success(state)
        # ManiSkill3's success_once: the condition held at some moment while physics ran
        # (e.g. the block was inside, then rolled out), not only at the end.
        success_once = success or (bool(result.ok) and self._success_seen)
        out = {
            "kind": state.kind,
            "success": success,
            "success_once": success_once,
            "rot_err_deg": float(rot[0]),
            "trans_err_m": float(trans[0]),
            "trans_err_raw_m": float(np.linalg.norm(T_pred[:3, 3] - T_gt[:3, 3])) if np.all(np.isfinite(T_pred)) else float("nan"),
            "point_err_m": float(point_err[0]),
            "point_mse": float(point_mse[0]),
            "executed": bool(result.ok),
            "at_rest": bool(result.at_rest),
            "failure_reason": "" if success else self._failure_reason(state, result),
            "failure_detail": "" if success else result.detail,
            "executor": self.executor,
            "grasp": self.grasp if self.executor in ("gripper", "panda") else "",
            "sim_seconds": result.sim_seconds,
            "observation_fallback": self.observation_fallback,
            "gt_cross_pose": T_gt.tolist(),
            "pred_cross_pose": T_pred.tolist() if np.all(np.isfinite(T_pred)) else None,
        }
        out.update(result.details)
        if state.kind == ARTICULATED:
            out["q_start"] = state.q_start
            out["q_final"] = self.furniture.qpos
            out["open_distance"] = self._open_distance(state.q_start)
        else:
            out["object"] = self.free_spec.name
            out["object_scale"] = self.free_scale
        return out

    def _failure_reason(self, state: StageState, result) -> str:
        """The code of a failed stage: the executor's own, else what the final state shows."""
        if result.reason:
            return failure.check_reason(result.reason)
        if state.kind == ARTICULATED:
            if self._open_distance(state.q_start) >= OPEN_TOLERANCE:
                return failure.NOT_OPEN_ENOUGH
            return failure.NOT_AT_REST
        center, rotation, half = self.furniture.in_region_world(self.root_pose)
        centroid = transform_points(pose_to_matrix(self.free_body.entity_pose), self.free_mesh.center_mass[None])[0]
        inside = bool(np.all(np.abs(rotation.T @ (centroid - center)) <= half))
        return failure.NOT_AT_REST if inside else failure.NOT_IN_REGION

    # ------------------------------------------------------------------ success
    def _open_distance(self, q_start: float) -> float:
        """|q_open - q_final| / |q_open - q_start| (docs/design.md)."""
        span = abs(self.asset.open_qpos - q_start)
        return abs(self.asset.open_qpos - self.furniture.qpos) / max(span, 1e-9)

    def door_open(self, q_start: float) -> bool:
        return self._open_distance(q_start) < OPEN_TOLERANCE and abs(self.furniture.qvel) < AT_REST_JOINT_SPEED

    def free_object_inside(self) -> bool:
        center, rotation, half = self.furniture.in_region_world(self.root_pose)
        centroid = transform_points(pose_to_matrix(self.free_body.entity_pose), self.free_mesh.center_mass[None])[0]
        local = rotation.T @ (centroid - center)
        return bool(np.all(np.abs(local) <= half) and self.free_object_at_rest())

    def free_object_at_rest(self) -> bool:
        """The free object's pose moved slower than AT_REST_LINEAR_SPEED and turned slower than
        AT_REST_ANGULAR_SPEED over each of its last STILL_STEPS physics steps. The pose, not
        PhysX's reported velocity, decides (``wpbench.sim.executor.ObservedMotion``); before the
        first physics step of an episode there is no motion to see and the reported velocity is used."""
        motion = getattr(self, "_free_motion", None)
        still = motion.still(AT_REST_LINEAR_SPEED, AT_REST_ANGULAR_SPEED, steps=STILL_STEPS) if motion else None
        if still is not None:
            return still
        return bool(np.linalg.norm(self.free_body.linear_velocity) < AT_REST_LINEAR_SPEED
                    and np.linalg.norm(self.free_body.angular_velocity) < AT_REST_ANGULAR_SPEED)

    def _stage_success(self, state: StageState) -> bool:
        return self.door_open(state.q_start) if state.kind == ARTICULATED else self.free_object_inside()

    def evaluate(self) -> dict:
        """``success``: every stage executed so far succeeded and the last stage is done.

        Success of each stage is judged on the state right after that stage's execution
        (``stage_result``); the episode succeeds when all stages did and the final state
        still satisfies the last one.
        """
        results = getattr(self, "stage_results", [])
        done = len(results) == len(self.STAGES) and len(self.STAGES) > 0
        ok = done and all(r["success"] for r in results)
        return {"success": torch.tensor([bool(ok)]), "stages_done": torch.tensor([len(results)])}


def _look_at(eye: np.ndarray, target: np.ndarray) -> sapien.Pose:
    """SAPIEN camera pose (x forward, y left, z up) at ``eye`` looking at ``target``."""
    T = np.eye(4)
    T[:3, :3] = look_at_frame(eye, target)
    T[:3, 3] = eye
    return matrix_to_pose(T)
