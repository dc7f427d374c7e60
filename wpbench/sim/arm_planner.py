"""The Panda's motion planner (mplib) as seen from wpbench: IK along TCP paths, collision
checks against the observed point cloud, and RRTConnect for free-space moves.

mplib runs in a child process (wpbench.sim.arm_planner_server, started once per process and
reused; wpbench.sim.arm_planner_env says why). This class moves every pose and cloud into
the robot's base frame before sending it, so the planner's robot always stands at its
origin. Arrays travel as lists. A dead or failing planner process raises
:class:`PlannerError`, which the executor turns into ``planning_failed``.
"""

from __future__ import annotations

import atexit
import pickle
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

MOVE_GROUP = "panda_hand_tcp"
# The links whose collisions with the observed cloud the planner refuses along a
# Cartesian path: the arm itself. The hand's own clearance is the grasp planners' job
# (wpbench.sim.side_entry checks hand and held object against the same cloud).
ARM_LINKS = tuple(f"panda_link{i}" for i in range(9))
HAND_LINKS = ("panda_hand", "panda_leftfinger", "panda_rightfinger", "panda_leftfinger_pad", "panda_rightfinger_pad")


class PlannerError(RuntimeError):
    """The planner process could not answer."""


def panda_files() -> tuple[Path, Path]:
    """The bundled ``panda_v2`` URDF and SRDF of the installed mani-skill."""
    import mani_skill

    root = Path(mani_skill.__file__).parent / "assets" / "robots" / "panda"
    return root / "panda_v2.urdf", root / "panda_v2.srdf"


def matrix_to_pose7(T: np.ndarray) -> list[float]:
    """(4, 4) -> [x, y, z, qw, qx, qy, qz] (mplib's pose layout)."""
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return [*map(float, T[:3, 3]), float(w), float(x), float(y), float(z)]


def pose7_to_matrix(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([p[4], p[5], p[6], p[3]]).as_matrix()
    T[:3, 3] = p[:3]
    return T


class ArmPlanner:
    """One mplib planner for the Panda; ``set_base`` says where the robot stands (world frame)."""

    _shared: "ArmPlanner | None" = None

    def __init__(self):
        from wpbench.sim.arm_planner_env import planner_environment

        urdf, srdf = panda_files()
        server = Path(__file__).with_name("arm_planner_server.py")
        self._proc = subprocess.Popen([sys.executable, str(server)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.DEVNULL, env=planner_environment())
        reply = self._call("init", urdf=str(urdf), srdf=str(srdf), move_group=MOVE_GROUP)
        self.joint_names = reply["joints"][:7]
        self.limits = np.asarray(reply["limits"], dtype=np.float64)
        self.base = np.eye(4)
        self._base_inv = np.eye(4)
        atexit.register(self.close)

    @classmethod
    def shared(cls) -> "ArmPlanner":
        """The process's planner (started on first use)."""
        if cls._shared is None or cls._shared._proc.poll() is not None:
            cls._shared = cls()
        return cls._shared

    def close(self) -> None:
        if self._proc.poll() is None:
            try:
                self._send({"op": "quit"})
                self._proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self._proc.kill()

    # ------------------------------------------------------------------ transport
    def _send(self, msg: dict) -> None:
        data = pickle.dumps(msg, protocol=4)
        self._proc.stdin.write(struct.pack("<I", len(data)) + data)
        self._proc.stdin.flush()

    def _call(self, op: str, **kwargs) -> dict:
        try:
            self._send({"op": op, **kwargs})
            head = self._proc.stdout.read(4)
            if len(head) < 4:
                raise PlannerError(f"the mplib planner process died (exit code {self._proc.poll()})")
            (n,) = struct.unpack("<I", head)
            reply = pickle.loads(self._proc.stdout.read(n))
        except (BrokenPipeError, OSError) as err:
            raise PlannerError(f"the mplib planner process is gone: {err}") from err
        if "error" in reply:
            raise PlannerError(f"mplib planner: {reply['error']}")
        return reply

    # ------------------------------------------------------------------ frames
    def set_base(self, base: np.ndarray) -> None:
        """The robot's base pose (4, 4) in the world; later poses and clouds are world-frame."""
        self.base = np.asarray(base, dtype=np.float64).copy()
        self._base_inv = np.linalg.inv(self.base)

    def _local(self, T: np.ndarray) -> list[float]:
        return matrix_to_pose7(self._base_inv @ T)

    def set_cloud(self, points: np.ndarray, radius: float) -> None:
        """Obstacles: world points (N, 3), each a ball of ``radius``."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        local = p @ self._base_inv[:3, :3].T + self._base_inv[:3, 3]
        self._call("cloud", points=local.tolist(), radius=float(radius))

    # ------------------------------------------------------------------ queries
    def ik(self, tcp: np.ndarray, seeds: np.ndarray, links=None) -> list[np.ndarray]:
        """Joint solutions (7,) for a world TCP pose, one per seed that converges collision-free."""
        reply = self._call("ik", pose=self._local(tcp), seeds=np.asarray(seeds, float).tolist(),
                           links=list(links) if links is not None else None)
        return [np.asarray(q) for q in reply["solutions"]]

    def chain(self, tcps: np.ndarray, seed: np.ndarray, links=ARM_LINKS) -> tuple[np.ndarray | None, dict]:
        """Joint path (K, 7) through world TCP poses (K, 4, 4), each solved from the last; (None, why) on failure."""
        reply = self._call("chain", poses=[self._local(T) for T in np.asarray(tcps).reshape(-1, 4, 4)],
                           seed=np.asarray(seed, float).tolist(), links=list(links) if links is not None else None)
        if not reply["ok"]:
            return None, reply
        return np.asarray(reply["path"], dtype=np.float64), reply

    def line_clear(self, start: np.ndarray, goal: np.ndarray, links=None) -> bool:
        """A straight joint-space move from ``start`` to ``goal`` (7,) touches no obstacle."""
        return bool(self._call("line", start=np.asarray(start, float).tolist(), goal=np.asarray(goal, float).tolist(),
                               links=list(links) if links is not None else None)["ok"])

    def rrt(self, start: np.ndarray, goal: np.ndarray, seconds: float = 1.0) -> np.ndarray | None:
        """RRTConnect joint path (M, 7) from ``start`` to ``goal``; None when none was found in time."""
        reply = self._call("rrt", start=np.asarray(start, float).tolist(), goals=[np.asarray(goal, float).tolist()],
                           seconds=float(seconds))
        return np.asarray(reply["path"], dtype=np.float64) if reply["ok"] else None

    def collisions(self, q: np.ndarray, links=None) -> list[str]:
        return list(self._call("collide", q=np.asarray(q, float).tolist(),
                               links=list(links) if links is not None else None)["links"])

    def fk(self, q: np.ndarray) -> np.ndarray:
        """World TCP pose (4, 4) of joint values ``q`` (7,)."""
        return self.base @ pose7_to_matrix(self._call("fk", q=np.asarray(q, float).tolist())["pose"])
