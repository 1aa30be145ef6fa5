"""The camera audit's visibility flag rebuilt as an outsider would (issue 38 item 7): from a
run's scene.json, trace.csv and URDFs only, with plain pybullet and numpy, by the test the
scene.json ``cameras.<name>.visibility`` text documents; then compared with the logged
``<prefix><i>_visible`` of every row.

    python tests/outsider_visibility.py results/chan2011/simulation_render [more runs]

prints, per run and camera, the rows and points that disagree and why each would flip.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pybullet as p


def _pose(d: dict[str, Any]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.asarray(p.getMatrixFromQuaternion(d["quaternion_xyzw"])).reshape(3, 3)
    T[:3, 3] = d["position"]
    return T


def _quat_pose(v: list[float]) -> np.ndarray:
    return _pose({"position": v[:3], "quaternion_xyzw": v[3:]})


def _collision_shape(client: int, part: dict[str, Any]) -> int:
    shape = part["shape"]
    if shape == "box":
        return p.createCollisionShape(p.GEOM_BOX, halfExtents=[s / 2 for s in part["size"]],
                                      physicsClientId=client)
    if shape == "cylinder":
        return p.createCollisionShape(p.GEOM_CYLINDER, radius=part["radius"],
                                      height=part["length"], physicsClientId=client)
    if shape == "capsule":
        return p.createCollisionShape(p.GEOM_CAPSULE, radius=part["radius"],
                                      height=part["length"], physicsClientId=client)
    if shape == "sphere":
        return p.createCollisionShape(p.GEOM_SPHERE, radius=part["radius"],
                                      physicsClientId=client)
    raise ValueError(f"unknown shape {shape}")


class World:
    """Every body with a collision shape, from scene.json (the physics client's bodies)."""

    def __init__(self, run_dir: Path, scene: dict[str, Any]) -> None:
        self.c = p.connect(p.DIRECT)
        self.scene = scene
        self.robots: dict[str, tuple[int, list[int], list[str], dict[str, int]]] = {}
        self.movers: dict[str, list[tuple[int, np.ndarray]]] = {}
        for b in scene["bodies"]:
            if not b.get("collision", False):
                continue
            if b["kind"] == "urdf":
                bp = b["base_pose"]
                bid = p.loadURDF(str(run_dir / b["urdf"]), bp["position"],
                                 bp["quaternion_xyzw"], useFixedBase=bool(b["use_fixed_base"]),
                                 flags=int(b["load_flags"]["value"]), physicsClientId=self.c)
                names = {p.getJointInfo(bid, j, physicsClientId=self.c)[1].decode(): j
                         for j in range(p.getNumJoints(bid, physicsClientId=self.c))}
                links = {p.getJointInfo(bid, j, physicsClientId=self.c)[12].decode(): j
                         for j in range(p.getNumJoints(bid, physicsClientId=self.c))}
                self.robots[b["name"]] = (bid, [names[j] for j in b["joints"]],
                                          list(b.get("q_columns") or []), links)
            else:
                parts = (b["parts"] if b["kind"] == "compound" else
                         [{**b, "shape": b["kind"], "T_body_part": {
                             "position": [0, 0, 0], "quaternion_xyzw": [0, 0, 0, 1]}}])
                T = _pose(b["pose"])
                ids = []
                for part in parts:
                    Tp = T @ _pose(part["T_body_part"])
                    q = p.getQuaternionFromMatrix(Tp[:3, :3].tolist()) if hasattr(
                        p, "getQuaternionFromMatrix") else _quat(Tp[:3, :3])
                    bid = p.createMultiBody(0.0, _collision_shape(self.c, part), -1,
                                            Tp[:3, 3].tolist(), q, physicsClientId=self.c)
                    ids.append((bid, _pose(part["T_body_part"])))
                if b.get("pose_columns"):
                    self.movers[b["name"]] = ids
                    self.mover_cols = getattr(self, "mover_cols", {})
                    self.mover_cols[b["name"]] = b["pose_columns"]

    def set_row(self, row: pd.Series) -> None:
        for bid, joints, cols, _ in self.robots.values():
            for j, col in zip(joints, cols, strict=False):
                p.resetJointState(bid, j, float(row[col]), physicsClientId=self.c)
        for name, ids in self.movers.items():
            v = [float(row[c]) for c in self.mover_cols[name]]
            if not np.all(np.isfinite(v)):
                continue
            T = _quat_pose(v)
            for bid, Tp in ids:
                Tw = T @ Tp
                p.resetBasePositionAndOrientation(bid, Tw[:3, 3].tolist(), _quat(Tw[:3, :3]),
                                                  physicsClientId=self.c)


def _quat(R: np.ndarray) -> list[float]:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_quat().tolist()


def _minor_axes(intr: dict[str, Any], T_wc: np.ndarray, T_wt: np.ndarray, pts: np.ndarray,
                radius: float) -> np.ndarray:
    """Minor axis [px] of each disc's image ellipse: the conic H^-T C0 H^-1 of the disc of
    ``radius`` centred on each point in its plane z = z_i of the target frame."""
    K = np.array([[intr["fu"], 0.0, intr["u0"]], [0.0, intr["fv"], intr["v0"]], [0, 0, 1]])
    T_ct = np.linalg.inv(T_wc) @ T_wt
    out = np.zeros(len(pts))
    for i, (cx, cy, cz) in enumerate(pts):
        H = K @ np.column_stack([T_ct[:3, 0], T_ct[:3, 1], cz * T_ct[:3, 2] + T_ct[:3, 3]])
        if abs(np.linalg.det(H)) < 1e-300:
            continue
        Hi = np.linalg.inv(H)
        C = Hi.T @ np.array([[1, 0, -cx], [0, 1, -cy], [-cx, -cy, cx * cx + cy * cy
                                                      - radius * radius]]) @ Hi
        A, b, c = C[:2, :2], C[:2, 2], C[2, 2]
        lam = np.linalg.eigvalsh(A)
        if lam[0] * lam[1] <= 0:
            continue
        if lam[1] < 0:
            A, b, c, lam = -A, -b, -c, -lam[::-1]
        k = b @ np.linalg.solve(A, b) - c
        out[i] = 2 * np.sqrt(k / lam[1]) if k > 0 else 0.0
    return out


def audit(run_dir: Path) -> list[str]:
    """Disagreements between the documented visibility test and the logged flag."""
    run_dir = Path(run_dir)
    scene = json.loads((run_dir / "scene.json").read_text())
    trace = pd.read_csv(run_dir / "trace.csv", low_memory=False)
    out: list[str] = []
    cams = scene.get("cameras") or {}
    if not cams:
        return out
    world = World(run_dir, scene)
    bodies = {b["name"]: b for b in scene["bodies"]}
    try:
        for name, cam in cams.items():
            text = cam["visibility"]
            ray_start = float(re.search(r"\(([0-9.e-]+) m out along the ray\)", text).group(1))
            lift = float(re.search(r"lifted ([0-9.e-]+) m", text).group(1))
            margin = float(re.search(r"before ([0-9.e-]+) m short", text).group(1))
            min_px = float(re.search(r"at least ([0-9.e-]+) px across", text).group(1))
            intr = cam["intrinsics"]
            tgt = bodies[cam["target"]]
            radius = float(tgt["dot"]["radius"])
            pts = np.asarray(tgt["points_target"], float)
            pre = cam["feature_prefix"]
            pose_cols = [f"{name}_{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]
            tcols = tgt.get("pose_columns")
            bad = 0
            for _, row in trace.iterrows():
                world.set_row(row)
                T_wc = _quat_pose([float(row[c]) for c in pose_cols])
                T_wt = (_quat_pose([float(row[c]) for c in tcols]) if tcols
                        else _pose(tgt["pose"]))
                n = T_wt[:3, 2]
                P = pts @ T_wt[:3, :3].T + T_wt[:3, 3]
                Pc = (P - T_wc[:3, 3]) @ T_wc[:3, :3]
                Z = Pc[:, 2]
                with np.errstate(divide="ignore", invalid="ignore"):
                    u = intr["fu"] * Pc[:, 0] / Z + intr["u0"]
                    v = intr["fv"] * Pc[:, 1] / Z + intr["v0"]
                inside = ((u >= -0.5) & (u <= intr["width"] - 0.5) & (v >= -0.5)
                          & (v <= intr["height"] - 0.5))
                c = T_wc[:3, 3]
                Pl = P + lift * n
                d = Pl - c
                L = np.linalg.norm(d, axis=1)
                start = c + ray_start * d / L[:, None]
                hits = p.rayTestBatch(start.tolist(), Pl.tolist(), physicsClientId=world.c)
                free = np.array([h[0] < 0 or h[2] * (Li - ray_start) >= Li - ray_start - margin
                                 for h, Li in zip(hits, L, strict=True)])
                front = (c - Pl) @ n > 0  # more than the lift above the dot's plane
                minor = _minor_axes(intr, T_wc, T_wt, pts, radius)
                mine = (Z > 0) & inside & front & free & (minor >= min_px)
                logged = np.array([str(row[f"{pre}{i + 1}_visible"]).lower() == "true"
                                   for i in range(len(pts))])
                for i in np.flatnonzero(mine != logged):
                    bad += 1
                    ang = np.degrees(np.arccos(np.clip((c - P[i]) @ n / np.linalg.norm(
                        c - P[i]), -1, 1)))
                    if bad <= 12:
                        out.append(f"{run_dir} {name} t={row['t']:.3f} point {i + 1}: logged "
                                   f"{logged[i]}, documented {mine[i]} (front {front[i]}, "
                                   f"lifted-front {(c - Pl[i]) @ n > 0}, free {free[i]}, "
                                   f"in image {inside[i]}, {ang:.2f} deg off the normal)")
            out.append(f"{run_dir} {name}: {bad} disagreements in {len(trace)} rows")
    finally:
        p.disconnect(world.c)
    return out


if __name__ == "__main__":
    for arg in sys.argv[1:]:
        for line in audit(Path(arg)):
            print(line)
