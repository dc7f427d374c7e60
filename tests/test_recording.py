"""RerunRecorder writes one readable .rrd per run with the scene, the prediction and the motion.

Most tests drive the recorder with a small stand-in env (real trimesh meshes and
SAPIEN poses, no simulator) so they run in a second; one test records a real
``gt`` run of ``open-then-place`` through ``run_benchmark``.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import sapien
import trimesh

rr = pytest.importorskip("rerun")

from wpbench.evaluation.recording import RecorderConfig, RerunRecorder  # noqa: E402


# ---------------------------------------------------------------------- reading an .rrd back
@dataclass
class RecordingContents:
    """What a .rrd holds, per entity path: component columns, timelines and rows."""

    components: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))
    timelines: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))
    batches: dict[str, list] = field(default_factory=lambda: defaultdict(list))

    def column(self, entity: str, component: str, timeline: str) -> list[tuple[int, object]]:
        """(time, value) rows of one component of one entity, sorted by ``timeline``."""
        rows = []
        for batch in self.batches[entity]:
            if component not in batch.schema.names or timeline not in batch.schema.names:
                continue
            times = batch.column(timeline).to_pylist()
            values = batch.column(component).to_pylist()
            rows += [(t, v) for t, v in zip(times, values) if v is not None]
        return sorted(rows, key=lambda r: r[0])


def read_recording(path: Path) -> RecordingContents:
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    assert len(reader.recordings()) == 1, "one run, one recording"
    contents = RecordingContents()
    for chunk in reader.stream():
        entity = chunk.entity_path.lstrip("/")
        batch = chunk.to_record_batch()
        contents.components[entity] |= {n for n in batch.schema.names if ":" in n}
        contents.timelines[entity] |= set(chunk.timeline_names)
        contents.batches[entity].append(batch)
    return contents


# ---------------------------------------------------------------------- a stand-in env
class FakeLink:
    def __init__(self, name: str, pose: sapien.Pose):
        self.name = name
        self.entity_pose = pose


class FakeFurniture:
    """Two links: a static body and a door that swings about z as qpos changes."""

    def __init__(self):
        self.body = FakeLink("scene-0-furniture_body", sapien.Pose([0.1, 0.0, 0.3]))
        self.door = FakeLink("scene-0-furniture_door", sapien.Pose([0.4, 0.0, 0.3]))
        self.links = [self.body, self.door]
        self.target_link = self.door
        self.qpos = 0.0

    def link_mesh(self, link):
        return trimesh.creation.box((0.4, 0.4, 0.4)) if link is self.body else trimesh.creation.box((0.02, 0.4, 0.4))

    def in_region_world(self, root_pose):
        return root_pose[:3, 3] + [0.0, 0.0, 0.3], root_pose[:3, :3], np.array([0.15, 0.15, 0.1])

    def swing(self, q: float) -> None:
        self.qpos = q
        self.door.entity_pose = sapien.Pose([0.4, 0.0, 0.3], [np.cos(q / 2), 0.0, 0.0, np.sin(q / 2)])


@dataclass
class FakeAsset:
    object_id: str = "oven_0001"
    category: str = "oven"


@dataclass
class FakeObjectSpec:
    name: str = "block"
    rgba: tuple = (0.9, 0.2, 0.1, 1.0)


class FakeBody:
    def __init__(self):
        self.entity_pose = sapien.Pose([1.0, 0.0, 0.05])


class FakeEnv:
    """The attributes of tasks.base.CrossPoseEnv the recorder reads, and its physics hook."""

    on_physics_step = None
    sim_freq = 200

    def __init__(self):
        self.furniture = FakeFurniture()
        self.asset = FakeAsset()
        self.free_spec = FakeObjectSpec()
        self.free_body = FakeBody()
        self.free_mesh = trimesh.creation.box((0.05, 0.05, 0.05))
        self.root_pose = np.eye(4)
        self.stage_index = 0
        self.stage_kind = "articulated"
        self.physics_steps = 0
        shift = np.eye(4)
        shift[:3, 3] = [0.0, 0.2, 0.0]
        self.truth = shift

    def ground_truth(self) -> dict:
        return {"cross_pose": self.truth, "kind": self.stage_kind, "stage": self.stage_index}

    def run_physics(self, steps: int) -> None:
        """What CrossPoseEnv.advance_physics does around the hook; the door opens and the block falls."""
        for _ in range(steps):
            self.furniture.swing(self.furniture.qpos + 0.01)
            p = self.free_body.entity_pose.p
            self.free_body.entity_pose = sapien.Pose([p[0], p[1], max(p[2] - 0.001, 0.0)])
            self.physics_steps += 1
            if self.on_physics_step is not None:
                self.on_physics_step(self)


def fake_obs(rng: np.random.Generator, na: int = 32, nb: int = 64) -> dict:
    return {"action_points": rng.normal(size=(na, 3)).astype(np.float32),
            "anchor_points": rng.normal(size=(nb, 3)).astype(np.float32)}


def stage_result(success: bool = True) -> dict:
    return {"kind": "articulated", "success": success, "rot_err_deg": 1.5, "trans_err_m": 0.01,
            "point_err_m": 0.02, "failure_reason": "" if success else "goal not reached", "q_final": 1.2}


def record_episode(recorder: RerunRecorder, env: FakeEnv, rng, transform, diagnostics, steps: int = 95) -> None:
    env.physics_steps = 0
    recorder.begin_episode(env, seed=7)
    recorder.log_prediction(env, fake_obs(rng), transform, diagnostics)
    env.run_physics(steps)
    recorder.log_stage_result(env, stage_result())
    recorder.end_episode(env, {"seed": 7, "object_id": env.asset.object_id, "category": env.asset.category,
                               "success": True, "stages": [stage_result()], "rot_err_deg": 1.5,
                               "trans_err_m": 0.01, "point_err_m": 0.02, "timings": {"episode_s": 0.5}})


# ---------------------------------------------------------------------- tests with the stand-in env
def test_episode_has_scene_prediction_metrics_and_motion(tmp_path):
    rng = np.random.default_rng(0)
    env = FakeEnv()
    path = tmp_path / "run.rrd"
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 0.1]
    diagnostics = {"flow": rng.normal(size=(32, 3)), "w": np.full(32, 0.25),
                   "action_targets": rng.normal(size=(32, 3)), "action_weights": rng.uniform(size=32)}
    with RerunRecorder(path, application="test", config=RecorderConfig(physics_stride=10)) as recorder:
        record_episode(recorder, env, rng, T, diagnostics)
    got = read_recording(path)

    assert "Mesh3D:vertex_positions" in got.components["world/furniture/door"]
    assert "Mesh3D:vertex_positions" in got.components["world/furniture/body"]
    assert "Mesh3D:vertex_positions" in got.components["world/object"]
    for entity in ("world/observation/action", "world/observation/anchor", "world/prediction/goal", "world/truth/goal"):
        assert "Points3D:positions" in got.components[entity], entity
    assert "Arrows3D:vectors" in got.components["world/prediction/flow"]
    region = got.column("world/truth/in_region", "Boxes3D:half_sizes", "sim_step")
    np.testing.assert_allclose(region[0][1], [[0.15, 0.15, 0.1]])
    assert "Arrows3D:vectors" in got.components["world/prediction/correspondences"]
    for entity in ("metrics/prediction/w", "metrics/articulated/success", "metrics/articulated/rot_err_deg",
                   "metrics/episode/success", "sim/target_joint"):
        assert "Scalars:scalars" in got.components[entity], entity
    assert "TextDocument:text" in got.components["episode/summary"]
    assert "TextLog:text" in got.components["log"]

    # The goals are the action points moved by each transform.
    action = np.asarray(got.column("world/observation/action", "Points3D:positions", "sim_step")[0][1])
    truth = np.asarray(got.column("world/truth/goal", "Points3D:positions", "sim_step")[0][1])
    pred = np.asarray(got.column("world/prediction/goal", "Points3D:positions", "sim_step")[0][1])
    np.testing.assert_allclose(truth - action, np.tile([0.0, 0.2, 0.0], (32, 1)), atol=1e-5)
    np.testing.assert_allclose(pred - action, np.tile([0.0, 0.0, 0.1], (32, 1)), atol=1e-5)
    assert got.column("metrics/prediction/w", "Scalars:scalars", "sim_step")[0][1] == pytest.approx([0.25])

    # Motion: the door pose at the start, every 10 physics steps, and after the stage.
    door = got.column("world/furniture/door", "Transform3D:quaternion", "sim_step")
    steps = [t for t, _ in door]
    assert steps == [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 95]
    angles = [2 * np.arctan2(q[0][2], q[0][3]) for _, q in door]   # xyzw quaternion about z
    np.testing.assert_allclose(angles, np.array(steps) * 0.01, atol=1e-5)
    heights = [v[0] for _, v in got.column("sim/object_height", "Scalars:scalars", "sim_step")]
    assert heights[0] > heights[-1], "the falling block is recorded"
    assert {"episode", "sim_step", "sim_time"} <= got.timelines["world/furniture/door"]
    summary = got.column("episode/summary", "TextDocument:text", "sim_step")[0][1][0]
    assert "oven_0001" in summary and "SUCCESS" in summary


def test_episodes_follow_one_another_and_old_scene_is_cleared(tmp_path):
    rng = np.random.default_rng(1)
    env = FakeEnv()
    path = tmp_path / "two.rrd"
    with RerunRecorder(path) as recorder:
        record_episode(recorder, env, rng, np.eye(4), {}, steps=40)
        record_episode(recorder, env, rng, np.eye(4), {}, steps=40)
    got = read_recording(path)
    door = got.column("world/furniture/door", "Transform3D:quaternion", "sim_step")
    steps = [t for t, _ in door]
    assert steps == sorted(steps) and len(set(steps)) == len(steps), "sim_step is monotonic over the run"
    episodes = sorted({e for e, _ in got.column("world/furniture/door", "Mesh3D:vertex_positions", "episode")})
    assert episodes == [0, 1]
    second_start = got.column("world/furniture/door", "Mesh3D:vertex_positions", "sim_step")[1][0]
    assert second_start > 40, "the second episode starts after the first one's steps"
    clears = got.column("world/furniture", "Clear:is_recursive", "sim_step")
    assert [t for t, _ in clears] == [0, second_start], "each episode clears the previous scene"


def test_hook_is_chained_and_given_back(tmp_path):
    rng = np.random.default_rng(2)
    env = FakeEnv()
    calls = []
    env.on_physics_step = lambda e: calls.append(e.physics_steps)
    with RerunRecorder(tmp_path / "hook.rrd", config=RecorderConfig(physics_stride=5)) as recorder:
        recorder.begin_episode(env, seed=0)
        assert env.on_physics_step is not None and env.on_physics_step.__self__ is recorder
        env.run_physics(12)
        recorder.log_stage_result(env, stage_result(success=False))
        recorder.end_episode(env, {"success": False, "stages": [stage_result(success=False)]})
    assert calls == list(range(1, 13)), "the hook that was there before still sees every step"
    env.on_physics_step(env)   # given back: the original callable
    assert calls[-1] == 12

    plain = FakeEnv()
    with RerunRecorder(tmp_path / "plain.rrd") as recorder:
        recorder.begin_episode(plain, seed=0)
        assert "on_physics_step" in plain.__dict__
        recorder.end_episode(plain, {"success": False, "stages": []})
    assert "on_physics_step" not in plain.__dict__ and plain.on_physics_step is None


def test_nan_prediction_and_batched_torch_diagnostics(tmp_path):
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(3)
    env = FakeEnv()
    path = tmp_path / "nan.rrd"
    diagnostics = {"flow": torch.randn(1, 32, 3), "w": torch.tensor([0.5]),
                   "action_targets": torch.randn(1, 17, 3)}   # wrong point count: reported, not drawn
    with RerunRecorder(path) as recorder:
        recorder.begin_episode(env, seed=0)
        recorder.log_prediction(env, fake_obs(rng), np.full((4, 4), np.nan), diagnostics)
    got = read_recording(path)
    assert "Points3D:positions" in got.components["world/truth/goal"]
    assert "world/prediction/goal" not in got.components, "a NaN cross-pose has no goal to show"
    flow = np.asarray(got.column("world/prediction/flow", "Arrows3D:vectors", "sim_step")[0][1])
    np.testing.assert_allclose(flow, diagnostics["flow"][0].numpy(), atol=1e-6)
    assert "world/prediction/correspondences" not in got.components
    warnings = " ".join(v[0] for _, v in got.column("log", "TextLog:text", "sim_step"))
    assert "no finite predicted cross-pose" in warnings and "action_targets" in warnings


def test_empty_run_leaves_a_valid_file_and_close_is_final(tmp_path):
    path = tmp_path / "sub" / "empty.rrd"
    recorder = RerunRecorder(path, application="empty")
    recorder.close()
    recorder.close()   # twice is fine
    got = read_recording(path)
    assert "ViewCoordinates:xyz" in got.components["world"]
    with pytest.raises(RuntimeError, match="closed"):
        recorder.begin_episode(FakeEnv(), seed=0)


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"\.rrd"):
        RerunRecorder(tmp_path / "run.txt")
    with pytest.raises(ValueError, match="physics_stride"):
        RecorderConfig(physics_stride=0)
    with RerunRecorder(tmp_path / "x.rrd") as recorder:
        recorder.begin_episode(FakeEnv(), seed=0)
        with pytest.raises(ValueError, match="action_points"):
            recorder.log_prediction(FakeEnv(), {"action_points": np.zeros((5, 2)), "anchor_points": np.zeros((5, 3))},
                                    np.eye(4), {})


# ---------------------------------------------------------------------- a real run
@pytest.mark.slow
def test_real_gt_run_is_recorded(tmp_path):
    pytest.importorskip("mani_skill")
    from wpbench.evaluation.runner import RunConfig, run_benchmark

    path = tmp_path / "x.rrd"
    recorder = RerunRecorder(path, application="wpbench gt open-then-place")
    try:
        summary = run_benchmark(RunConfig(policy="gt", task="open-then-place", episodes=1, obs="mesh",
                                          out=tmp_path / "run"), observer=recorder)
    finally:
        recorder.close()
    got = read_recording(path)

    furniture = [e for e in got.components if e.startswith("world/furniture/")]
    assert any("Mesh3D:vertex_positions" in got.components[e] for e in furniture), furniture
    assert "Mesh3D:vertex_positions" in got.components["world/object"]
    for entity in ("world/observation/action", "world/observation/anchor", "world/prediction/goal", "world/truth/goal"):
        assert "Points3D:positions" in got.components[entity], entity
    # gt: the predicted goal is the true goal, for both stages.
    pred = got.column("world/prediction/goal", "Points3D:positions", "sim_step")
    truth = got.column("world/truth/goal", "Points3D:positions", "sim_step")
    assert len(pred) == len(truth) == 2
    for (_, p), (_, t) in zip(pred, truth):
        np.testing.assert_allclose(np.asarray(p), np.asarray(t), atol=1e-4)
    for entity in ("metrics/articulated/success", "metrics/free-floating/success", "metrics/episode/success"):
        assert "Scalars:scalars" in got.components[entity], entity
    success = got.column("metrics/episode/success", "Scalars:scalars", "sim_step")[0][1][0]
    assert success == float(summary["successes"]), "the recorded outcome is the run's outcome"
    # Motion: the free object and the links were logged at many physics steps.
    object_steps = [t for t, _ in got.column("world/object", "Transform3D:translation", "sim_step")]
    assert len(object_steps) > 5
    def pose_rows(entity):
        quats = got.column(entity, "Transform3D:quaternion", "sim_step")
        trans = got.column(entity, "Transform3D:translation", "sim_step")
        return [np.concatenate([np.ravel(q), np.ravel(t)]) for (_, q), (_, t) in zip(quats, trans)]

    moving = [e for e in furniture if len(rows := pose_rows(e)) > 5 and not np.allclose(rows[0], rows[-1], atol=1e-3)]
    assert moving, "the door or drawer moves during the articulated stage"
    joint = [v[0] for _, v in got.column("sim/target_joint", "Scalars:scalars", "sim_step")]
    record = json.loads((tmp_path / "run" / "episodes.jsonl").read_text().splitlines()[0])
    assert joint[0] == pytest.approx(record["stages"][0]["q_start"], abs=1e-4)
    assert joint[-1] == pytest.approx(record["stages"][0]["q_final"], abs=1e-4)
    assert "TextDocument:text" in got.components["episode/summary"]
    assert not [e for e in got.components if e.startswith(("world/robot", "world/executor"))], \
        "an ideal run has no robot to draw"


# ---------------------------------------------------------------------- the robot's visual meshes
def test_urdf_visuals_are_read_in_the_link_frame(tmp_path):
    from wpbench.evaluation.recording_robot import urdf_link_name, urdf_visual_meshes

    trimesh.creation.box((0.2, 0.1, 0.05)).export(tmp_path / "part.obj")
    (tmp_path / "robot.urdf").write_text("""<robot name="r">
  <material name="red"><color rgba="1 0 0 1"/></material>
  <link name="base">
    <visual><origin xyz="0 0 0.5" rpy="0 0 1.5707963267948966"/><geometry><mesh filename="part.obj"/></geometry>
      <material name="red"/></visual>
    <visual><origin xyz="1 0 0"/><geometry><box size="0.1 0.1 0.1"/></geometry></visual>
  </link>
  <link name="tool"/>
  <link name="lost"><visual><geometry><mesh filename="missing.obj"/></geometry></visual></link>
</robot>""")
    meshes = urdf_visual_meshes(str(tmp_path / "robot.urdf"))
    assert set(meshes) == {"base"}, "links without (readable) visuals are left to the collision shapes"
    base = meshes["base"]
    # The mesh turned a quarter turn about z and raised 0.5 m, and the box 1 m along x.
    np.testing.assert_allclose(base.bounds, [[-0.05, -0.1, -0.05], [1.05, 0.1, 0.525]], atol=1e-6)
    colors = np.unique(np.asarray(base.visual.vertex_colors), axis=0)
    assert [255, 0, 0, 255] in colors.tolist(), "the URDF material colours the mesh"
    assert urdf_link_name("scene-0-panda_panda_leftfinger_pad", ["panda_leftfinger", "panda_leftfinger_pad"]) \
        == "panda_leftfinger_pad"
    assert urdf_link_name("scene-0-gripper_panda_hand", ["panda_hand_tcp", "panda_hand"]) == "panda_hand"
    assert urdf_link_name("scene-0-furniture_door", ["panda_hand"]) is None


# ---------------------------------------------------------------------- real gripper and panda runs
def _robot_run(tmp_path, executor: str):
    pytest.importorskip("mani_skill")
    from wpbench.evaluation.runner import RunConfig, run_benchmark

    path = tmp_path / f"{executor}.rrd"
    recorder = RerunRecorder(path, application=f"wpbench gt open-door {executor}")
    try:
        run_benchmark(RunConfig(policy="gt", task="open-door", episodes=1, obs="mesh", executor=executor,
                                out=tmp_path / "run"), observer=recorder, progress=False)
    finally:
        recorder.close()
    record = json.loads((tmp_path / "run" / "episodes.jsonl").read_text().splitlines()[0])
    return read_recording(path), record["stages"][0]


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["gripper", "panda"])
def test_robot_grasp_plan_and_motion_are_recorded(tmp_path, executor):
    got, stage = _robot_run(tmp_path, executor)
    assert stage["executor"] == executor and stage["grasp_point"] is not None

    # The robot: meshes of its URDF visuals, poses on the time line while it works.
    links = ["panda_hand", "panda_leftfinger", "panda_rightfinger"]
    if executor == "panda":
        links += [f"panda_link{i}" for i in range(8)]
    for link in links:
        assert "Mesh3D:vertex_positions" in got.components[f"world/robot/{link}"], link
    hand = got.column("world/robot/panda_hand", "Transform3D:translation", "sim_step")
    assert len({t for t, _ in hand}) > 1, "the hand has poses at more than one time"
    positions = np.array([np.ravel(p) for _, p in hand])
    assert np.ptp(positions, axis=0).max() > 0.05, "the hand moves"
    assert np.abs(positions).max() < 3.0, "no pose of the parked robot is drawn"
    scale = [(t, np.ravel(v)[0]) for t, v in got.column("world/robot", "Transform3D:scale", "sim_step")]
    assert [s == 1.0 for _, s in scale] == [False, True, False], "parked, working, parked again"
    assert scale[1][0] <= hand[0][0] and hand[-1][0] < scale[2][0]
    if executor == "panda":
        base = np.array([np.ravel(p) for _, p in got.column("world/robot/panda_link0", "Transform3D:translation",
                                                              "sim_step")])
        np.testing.assert_allclose(base, np.tile(stage["arm_base"], (len(base), 1)), atol=1e-3)
        wrist = np.array([np.ravel(p) for _, p in got.column("world/robot/panda_link7", "Transform3D:translation",
                                                               "sim_step")])
        assert np.ptp(wrist, axis=0).max() > 0.05, "the arm's links move"

    # The grasp, its approach and the planned path are the executor's, at the stage's start.
    (t_grasp, grasp), = got.column("world/executor/grasp_point", "Points3D:positions", "sim_step")
    np.testing.assert_allclose(np.ravel(grasp), stage["grasp_point"], atol=1e-5)
    (_, origin), = got.column("world/executor/grasp_approach", "Arrows3D:origins", "sim_step")
    (_, vector), = got.column("world/executor/grasp_approach", "Arrows3D:vectors", "sim_step")
    np.testing.assert_allclose(np.ravel(origin) + np.ravel(vector), stage["grasp_point"], atol=1e-5)
    np.testing.assert_allclose(np.ravel(vector) / np.linalg.norm(vector), stage["grasp_approach"], atol=1e-3)
    (t_plan, planned), = got.column("world/executor/planned_path", "LineStrips3D:strips", "sim_step")
    np.testing.assert_allclose(np.asarray(planned[0]), stage["planned_path"], atol=1e-5)
    assert t_grasp == t_plan == scale[0][0], "logged when the stage began (open-door: when the episode did)"

    # The executed TCP path: where the TCP went, through the grasp and along the plan.
    (t_exec, executed), = got.column("world/executor/executed_path", "LineStrips3D:strips", "sim_step")
    executed = np.asarray(executed[0])
    assert t_exec >= hand[-1][0] and len(executed) == len(hand)
    assert np.linalg.norm(executed - stage["grasp_point"], axis=1).min() < 0.02, "the TCP reached the grasp point"
    assert np.linalg.norm(executed - stage["planned_path"][-1], axis=1).min() < 0.05, "... and the plan's end"
