"""The mplib side of the Panda's planner: a small request/reply loop run in its own process.

mplib's compiled extension (0.1.1, the version mani-skill pins) was built against numpy 1
and crashes in a process whose numpy is 2.x, as wpbench's is. So it runs here, in a child
process whose ``PYTHONPATH`` puts numpy 1.26 first (wpbench.sim.arm_planner_env), and
talks to wpbench.sim.arm_planner through pipes. This file imports only the standard
library, numpy and mplib: it is run as a script, never imported by wpbench.

Protocol: each message is a 4-byte little-endian length and a pickle (protocol 4) of
plain Python values (dicts, lists, floats, strings): arrays travel as nested lists, so
the two numpy versions never unpickle each other's arrays. Everything is in the robot's
base frame (the client moves poses and clouds into it). mplib's own prints go to stderr.

Requests (``op``): ``ik`` (CLIK with joint limits from given seeds), ``chain`` (IK along a
sequence of TCP poses, each seeded with the last, refusing jumps, joint limits and
collisions of the listed links with the point cloud; a pose whose solution touches the
cloud is solved again from nudged seeds, a small collision-free change taken instead),
``collide`` (which links of a configuration touch the cloud), ``line`` (a straight joint-space move, collision-checked
at a fine step), ``rrt`` (RRTConnect with the point cloud), ``cloud`` (replace the point
cloud), ``fk`` (TCP pose of a configuration), ``quit``.
"""

from __future__ import annotations

import os
import pickle
import struct
import sys

import numpy as np

# A chain pose whose solution (seeded with the last pose's) touches the cloud is solved
# again from seeds with one of these joints nudged by these amounts (rad); a solution
# that touches nothing and changes no joint by more than ESCAPE_STEP (rad) from the last
# pose's is taken instead.
ESCAPE_JOINTS = (0, 2, 4, 6, 1, 3, 5)
ESCAPE_NUDGES = (0.1, -0.1, 0.25, -0.25, 0.5, -0.5)
ESCAPE_STEP = 0.2
ESCAPE_DRIFT = 0.01   # m, the TCP between the two poses keeps this close to the line joining them


def _read(stream):
    head = stream.read(4)
    if len(head) < 4:
        return None
    (n,) = struct.unpack("<I", head)
    return pickle.loads(stream.read(n))


def _write(stream, value) -> None:
    data = pickle.dumps(value, protocol=4)
    stream.write(struct.pack("<I", len(data)) + data)
    stream.flush()


class Server:
    def __init__(self, urdf: str, srdf: str, move_group: str):
        import mplib

        self.planner = mplib.Planner(urdf=urdf, srdf=srdf, move_group=move_group)
        self.model = self.planner.pinocchio_model
        self.world = self.planner.planning_world
        self.tcp_index = self.planner.link_name_2_idx[move_group]
        self.arm = list(self.planner.move_group_joint_indices)
        self.n = len(self.planner.user_joint_names)
        self.limits = np.asarray(self.planner.joint_limits, dtype=np.float64).reshape(-1, 2)
        self.has_cloud = False

    # ------------------------------------------------------------------ helpers
    def _full(self, q):
        q = np.asarray(q, dtype=np.float64)
        if len(q) == self.n:
            return q.copy()
        full = np.zeros(self.n)
        full[self.arm] = q
        full[len(self.arm):] = self.limits[len(self.arm):, 1]
        return full

    def _fk(self, q):
        self.model.compute_forward_kinematics(self._full(q))
        return np.asarray(self.model.get_link_pose(self.tcp_index), dtype=np.float64)

    def _error(self, pose, q):
        got = self._fk(q)
        d = float(np.linalg.norm(got[:3] - pose[:3]))
        dot = abs(float(np.dot(got[3:], pose[3:])))
        return d, 2.0 * float(np.arccos(min(1.0, dot)))

    def _within_limits(self, q) -> bool:
        lo, hi = self.limits[self.arm, 0], self.limits[self.arm, 1]
        return bool(np.all(q[self.arm] >= lo - 1e-4) and np.all(q[self.arm] <= hi + 1e-4))

    def _hits(self, q, links):
        """Links of ``links`` (all when None) that touch the point cloud or another object at ``q``."""
        if not self.has_cloud:
            return []
        full = self._full(q)
        self.world.set_use_point_cloud(True)
        self.world.set_use_attach(False)
        self.planner.robot.set_qpos(full, True)
        names = set()
        for c in self.world.collide_with_others():
            for name in (c.link_name1, c.link_name2):
                if name and name != "point_cloud" and (links is None or name in links):
                    names.add(name)
        return sorted(names)

    def _solve(self, pose, seed, pos_tol, ang_tol):
        q, ok, _ = self.model.compute_IK_CLIK_JL(self.tcp_index, np.asarray(pose, dtype=np.float64), self._full(seed),
                                                 self.limits[:, 0], self.limits[:, 1], 1e-5, 300)
        q = np.asarray(q, dtype=np.float64)
        if not self._within_limits(q):
            return None
        d, a = self._error(pose, q)
        return q if (d < pos_tol and a < ang_tol) else None

    # ------------------------------------------------------------------ requests
    def ik(self, pose, seeds, links=None, pos_tol=2e-3, ang_tol=2e-2):
        out = []
        for seed in seeds:
            q = self._solve(pose, seed, pos_tol, ang_tol)
            if q is None or any(np.abs(np.asarray(o) - q[self.arm]).max() < 0.1 for o in out):
                continue
            if not self._hits(q, links):
                out.append(q[self.arm].tolist())
        return {"solutions": out}

    def _sidestep(self, pose, q_prev, links, pos_tol, ang_tol):
        """A collision-free solution of ``pose`` near ``q_prev`` found from seeds with one
        joint nudged (ESCAPE_NUDGES): the redundant arm turns its elbow away from what it
        would touch; the smallest joint change within ESCAPE_STEP wins, None when none is."""
        best, best_step = None, None
        for j in ESCAPE_JOINTS:
            for d in ESCAPE_NUDGES:
                seed = q_prev.copy()
                seed[self.arm[j]] += d
                q = self._solve(pose, seed, pos_tol, ang_tol)
                if q is None:
                    continue
                step = float(np.max(np.abs(q[self.arm] - q_prev[self.arm])))
                if step > ESCAPE_STEP or (best_step is not None and step >= best_step):
                    continue
                if not self._hits(q, links) and self._between_ok(q_prev, q, pose, links):
                    best, best_step = q, step
        return best

    def _between_ok(self, a, b, pose, links):
        """The straight joint move from ``a`` to ``b`` (full) keeps its TCP within ESCAPE_DRIFT
        of the straight line to ``pose`` and touches nothing."""
        start = self._fk(a)[:3]
        for u in (0.25, 0.5, 0.75):
            q = (1 - u) * a + u * b
            line = (1 - u) * start + u * np.asarray(pose[:3], dtype=np.float64)
            if np.linalg.norm(self._fk(q)[:3] - line) > ESCAPE_DRIFT or self._hits(q, links):
                return False
        return True

    def chain(self, poses, seed, links=None, max_step=0.3, pos_tol=3e-3, ang_tol=3e-2):
        q_prev = self._full(seed)
        path = []
        for k, pose in enumerate(poses):
            q = self._solve(pose, q_prev, pos_tol, ang_tol)
            if q is None:
                return {"ok": False, "index": k, "why": "ik"}
            if float(np.max(np.abs(q[self.arm] - q_prev[self.arm]))) > max_step:
                return {"ok": False, "index": k, "why": "jump"}
            hits = self._hits(q, links)
            if hits:
                q = self._sidestep(pose, q_prev, links, pos_tol, ang_tol)
                if q is None:
                    return {"ok": False, "index": k, "why": "collision", "links": hits}
            path.append(q[self.arm].tolist())
            q_prev = q
        return {"ok": True, "path": path}

    def line(self, start, goal, step=0.02, links=None):
        a, b = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
        n = max(1, int(np.ceil(np.max(np.abs(b - a)) / step)))
        for u in np.linspace(0.0, 1.0, n + 1):
            hits = self._hits((1 - u) * a + u * b, links)
            if hits:
                return {"ok": False, "links": hits}
        return {"ok": True}

    def rrt(self, start, goals, seconds=1.0):
        self.world.set_use_point_cloud(self.has_cloud)
        self.world.set_use_attach(False)
        start = self._full(start)
        self.planner.robot.set_qpos(start, True)
        status, path = self.planner.planner.plan(start[self.arm], [np.asarray(g, dtype=np.float64) for g in goals],
                                                 planner_name="RRTConnect", time=float(seconds), range=0.1)
        if status != "Exact solution":
            return {"ok": False, "status": str(status)}
        return {"ok": True, "path": np.asarray(path, dtype=np.float64).tolist()}

    def cloud(self, points, radius):
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(pts) == 0:
            pts = np.array([[1e3, 1e3, 1e3]])
        self.world.update_point_cloud(pts, float(radius))
        self.has_cloud = True
        return {"ok": True}

    def collide(self, q, links=None):
        return {"links": self._hits(q, links)}

    def fk(self, q):
        return {"pose": self._fk(q).tolist()}


def main() -> None:
    # The protocol keeps the real stdout; anything mplib prints goes to stderr.
    proto = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    inp = sys.stdin.buffer
    server = None
    while True:
        msg = _read(inp)
        if msg is None or msg.get("op") == "quit":
            return
        op = msg.pop("op")
        try:
            if op == "init":
                server = Server(**msg)
                reply = {"ok": True, "joints": server.planner.user_joint_names,
                         "limits": server.limits[server.arm].tolist()}
            else:
                reply = getattr(server, op)(**msg)
        except Exception as err:  # a bad request is reported to the client, the loop goes on
            reply = {"error": f"{type(err).__name__}: {err}"}
        _write(proto, reply)


if __name__ == "__main__":
    main()
