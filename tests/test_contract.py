"""The env's public contract, as its users meet it.

- No module outside ``tasks/`` reaches into the env's private state.
- Ground truth leaves the env only through ``ground_truth()``, and only privileged
  policies receive it: every other registered policy answers the same when it is scrambled.
- A task of one's own, registered the documented way, runs through ``wpbench run``.
"""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from wpbench import names
from wpbench.evaluation.runner import run_episode
from wpbench.policies.registry import available_policies, make_policy

REPO = Path(__file__).resolve().parents[1]
WPBENCH = Path(sys.executable).with_name("wpbench")
# Expressions that hold an env: env, base, self.env, x.unwrapped, train_env, ...
ENV_NAME = re.compile(r"(^|_)(env|base)$|^unwrapped$")


def private_env_accesses(source: str) -> list[str]:
    """``line: expression`` for every ``<env>._name`` (or ``getattr(<env>, "_name")``) in ``source``."""
    found = []

    def holds_env(node: ast.AST) -> bool:
        name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
        return bool(ENV_NAME.search(name))

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__") \
                and holds_env(node.value):
            found.append(f"{node.lineno}: {ast.unparse(node)}")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("getattr", "setattr") \
                and len(node.args) >= 2 and holds_env(node.args[0]) and isinstance(node.args[1], ast.Constant) \
                and str(node.args[1].value).startswith("_") and not str(node.args[1].value).startswith("__"):
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_the_private_access_check_finds_what_it_should():
    source = textwrap.dedent("""
        base = env.unwrapped
        a = base._stage_state
        b = env.unwrapped._obs_cache
        c = getattr(base, "_observation_fallback", False)
        self.env._rng_counter = -1
        ok = base.ground_truth(), env.__class__, self._private, recorder._hook
    """)
    assert [line.split(": ")[1] for line in private_env_accesses(source)] == [
        "base._stage_state", "env.unwrapped._obs_cache", "getattr(base, '_observation_fallback', False)",
        "self.env._rng_counter"]


def test_no_module_outside_tasks_touches_private_env_state():
    offenders = []
    for path in sorted(REPO.rglob("*.py")):
        rel = path.relative_to(REPO)
        if rel.parts[0] in {"tasks", ".venv", ".git"} or rel == Path("tests/test_contract.py"):
            continue
        offenders += [f"{rel}:{hit}" for hit in private_env_accesses(path.read_text())]
    assert not offenders, "use the env's public methods (ground_truth, reset options, ...):\n" + "\n".join(offenders)


def test_privileged_policies_are_the_registered_ones_that_use_ground_truth():
    privileged = {name for name in available_policies() if make_policy(name).uses_ground_truth}
    assert privileged == set(names.PRIVILEGED_POLICIES)


class Spy:
    """Wraps a policy and keeps what ``predict`` was given and answered."""

    def __init__(self, policy):
        self.policy, self.calls = policy, []
        self.uses_ground_truth = policy.uses_ground_truth

    def predict(self, obs, info=None):
        out = self.policy.predict(obs, info)
        self.calls.append((sorted(obs), info, out.transform.copy()))
        return out


def scrambled(truth: dict) -> dict:
    """Ground truth with every field wrong: another pose, the other kind, another stage."""
    wrong = np.eye(4)
    wrong[:3, 3] = [0.3, -0.2, 0.4]
    other = names.FREE if truth["kind"] == names.ARTICULATED else names.ARTICULATED
    return {"cross_pose": wrong, "kind": other, "stage": truth["stage"] + 7}


@pytest.fixture(scope="module")
def two_stage_env():
    names.import_task("open-then-place")
    env = gym.make(names.TASKS["open-then-place"].env_id, obs_mode="mesh", assets="procedural", split="val")
    yield env
    env.close()


def answers(env, policy, seed: int, scramble: bool) -> list:
    base = env.unwrapped
    true_ground_truth = type(base).ground_truth
    spy = Spy(policy)
    if scramble:
        base.ground_truth = lambda: scrambled(true_ground_truth(base))
    try:
        run_episode(env, spy, seed)
    finally:
        base.__dict__.pop("ground_truth", None)
    return spy.calls


@pytest.mark.parametrize("name", [n for n in available_policies() if n not in names.PRIVILEGED_POLICIES])
def test_non_privileged_policies_see_only_the_clouds_and_ignore_scrambled_truth(two_stage_env, name):
    policy = make_policy(name)
    plain = answers(two_stage_env, policy, seed=3, scramble=False)
    mixed = answers(two_stage_env, policy, seed=3, scramble=True)
    assert len(plain) == len(mixed) == 2
    for (keys, info, transform), (_, info_scrambled, transform_scrambled) in zip(plain, mixed):
        assert keys == ["action_points", "anchor_points"] and info is None and info_scrambled is None
        np.testing.assert_array_equal(transform, transform_scrambled)


def test_scrambled_truth_reaches_the_privileged_policies(two_stage_env):
    """The scramble is real: gt, which reads the truth, answers differently under it."""
    plain = answers(two_stage_env, make_policy("gt"), seed=3, scramble=False)
    mixed = answers(two_stage_env, make_policy("gt"), seed=3, scramble=True)
    assert plain[0][1]["kind"] == names.ARTICULATED and mixed[0][1]["kind"] == names.FREE
    assert not np.allclose(plain[0][2], mixed[0][2])


PLUGIN = '''
"""A throw-away task: open a door that starts half open."""
import numpy as np
from mani_skill.utils.registration import register_env

from wpbench.names import ARTICULATED, register_task
from wpbench.tasks.base import CrossPoseEnv


@register_env("wpbench-plugin/OpenHalfOpenDoor-v0", max_episode_steps=1)
class OpenHalfOpenDoorEnv(CrossPoseEnv):
    """
    **Task Description:** open a door that starts half open.

    **Randomizations:** as OpenDoor-v0, but the door starts at half of its range.

    **Success Conditions:** as OpenDoor-v0.
    """

    STAGES = (ARTICULATED,)

    def _initialize_task(self, rng: np.random.Generator, options: dict) -> None:
        self.furniture.set_target_qpos(self.joint_fraction(0.5))


register_task("open-half-open-door", "wpbench-plugin/OpenHalfOpenDoor-v0", __name__, (ARTICULATED,))
'''


def test_a_task_of_ones_own_runs_through_wpbench_run(tmp_path):
    (tmp_path / "my_tasks.py").write_text(PLUGIN)
    env = {**os.environ, "PYTHONPATH": str(tmp_path), names.PLUGINS_VARIABLE: "my_tasks"}
    out = tmp_path / "run"
    cmd = [str(WPBENCH), "run", "--policy", "gt", "--task", "open-half-open-door", "--obs", "mesh",
           "--episodes", "2", "--out", str(out), "--no-progress"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes"] == 2 and summary["success_rate"] == 1.0
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert [r["task"] for r in records] == ["open-half-open-door"] * 2

    without = subprocess.run(cmd, env={**env, names.PLUGINS_VARIABLE: ""}, capture_output=True, text=True, timeout=300)
    assert without.returncode == 2 and "unknown task 'open-half-open-door'" in without.stderr

    broken = subprocess.run(cmd, env={**env, names.PLUGINS_VARIABLE: "no_such_module"}, capture_output=True,
                            text=True, timeout=300)
    assert broken.returncode == 2 and "WPBENCH_PLUGINS names module 'no_such_module'" in broken.stderr


def test_policy_groups_match_the_registry_and_the_training_specs():
    from wpbench.training.specs import POLICY_SPECS

    registered = set(available_policies())
    assert set(names.TRAINABLE_POLICIES) == set(POLICY_SPECS)
    assert set(names.WEIGHTED_POSE_VARIANTS) == {n for n, spec in POLICY_SPECS.items() if spec.model == "weightedpose"}
    for group in (names.TRAINABLE_POLICIES, names.PRIVILEGED_POLICIES, names.WEIGHTED_POLICIES):
        assert set(group) <= registered
