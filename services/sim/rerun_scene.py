"""The MuJoCo scene in rerun: geoms logged once, moving bodies' poses on sim time.

Every visible geom becomes a static rerun primitive under `world/bodies/<body>/<geom>`,
placed in its body's frame (boxes, spheres and ellipsoids as `Ellipsoids3D`/`Boxes3D`,
cylinders and capsules as `Capsules3D`-like shapes, meshes as `Mesh3D`). Bodies are
logged flat (not nested), each with its world pose, so a moving body's pose is one
`Transform3D` per log; static bodies are logged once.
"""

from __future__ import annotations

import mujoco
import numpy as np
import rerun as rr
from numpy.typing import NDArray

from common.recording import is_recording

G = mujoco.mjtGeom


def _body_path(model: mujoco.MjModel, body: int) -> str:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or f"body{body}"
    return f"world/bodies/{name}"


def _color(model: mujoco.MjModel, geom: int) -> NDArray[np.uint8]:
    mat = model.geom_matid[geom]
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[geom]
    return (np.clip(rgba, 0.0, 1.0) * 255).astype(np.uint8)


def _geom_archetype(model: mujoco.MjModel, geom: int) -> rr.AsComponents | None:
    kind = model.geom_type[geom]
    size = model.geom_size[geom]
    color = _color(model, geom)
    if kind == G.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[size], colors=[color], fill_mode="solid")
    if kind in (G.mjGEOM_SPHERE, G.mjGEOM_ELLIPSOID):
        radii = [size[0]] * 3 if kind == G.mjGEOM_SPHERE else size
        return rr.Ellipsoids3D(half_sizes=[radii], colors=[color], fill_mode="solid")
    if kind in (G.mjGEOM_CYLINDER, G.mjGEOM_CAPSULE):
        # rerun's capsules start at the origin and run along +z.
        return rr.Capsules3D(
            lengths=[2 * size[1]],
            radii=[size[0]],
            translations=[[0.0, 0.0, -size[1]]],
            colors=[color],
            fill_mode="solid",
        )
    if kind == G.mjGEOM_MESH:
        mesh = model.geom_dataid[geom]
        v0, nv = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        f0, nf = model.mesh_faceadr[mesh], model.mesh_facenum[mesh]
        return rr.Mesh3D(
            vertex_positions=model.mesh_vert[v0 : v0 + nv],
            triangle_indices=model.mesh_face[f0 : f0 + nf],
            albedo_factor=color,
        )
    if kind == G.mjGEOM_PLANE:
        half = size[:2] if size[0] > 0 else (50.0, 50.0)
        return rr.Boxes3D(half_sizes=[[half[0], half[1], 0.001]], colors=[color], fill_mode="solid")
    return None


class SceneLogger:
    """Logs a compiled model's geoms once and the moving bodies' poses on demand."""

    def __init__(self, rec: rr.RecordingStream, model: mujoco.MjModel, groups: set[int]) -> None:
        self.rec = rec
        self.model = model
        self.paths = [_body_path(model, b) for b in range(model.nbody)]
        self._groups = groups
        static: list[int] = []
        moving: list[int] = []
        for b in range(1, model.nbody):
            root = model.body_rootid[b]
            is_static = model.body_weldid[b] == 0 and model.body_mocapid[root] < 0
            (static if is_static else moving).append(b)
        self.static_bodies = static
        self.moving_bodies = np.array(moving, dtype=np.intp)
        #: The last pose logged per moving body (x y z, qw qx qy qz); NaN: none yet.
        self._logged = np.full((len(moving), 7), np.nan)

    def log_geometry(self, data: mujoco.MjData) -> None:
        """Every visible geom, static, in its body's frame; static bodies' poses."""
        if not is_recording(self.rec):
            return
        m = self.model
        for g in range(m.ngeom):
            if m.geom_group[g] not in self._groups or m.geom_rgba[g][3] == 0:
                continue
            arch = _geom_archetype(m, g)
            if arch is None:
                continue
            body = m.geom_bodyid[g]
            path = f"{self.paths[body]}/geom{g}"
            self.rec.log(
                path,
                rr.Transform3D(translation=m.geom_pos[g], quaternion=_xyzw(m.geom_quat[g])),
                static=True,
            )
            self.rec.log(path, arch, static=True)
        for b in self.static_bodies:
            self.rec.log(self.paths[b], self._pose(data, b), static=True)

    def log_poses(self, data: mujoco.MjData) -> None:
        """The world pose of every body that can move (robot, artifacts, people) and has
        since it was last logged (`POSE_MOVED`): an artifact on its table or a person
        standing costs nothing until they move."""
        if not is_recording(self.rec):
            return
        b = self.moving_bodies
        now = np.hstack([data.xpos[b], data.xquat[b]])
        moved = ~(np.abs(now - self._logged) <= POSE_MOVED).all(axis=1)  # NaN: never logged
        for k in np.flatnonzero(moved):
            self.rec.log(self.paths[b[k]], self._pose(data, int(b[k])))
        self._logged[moved] = now[moved]

    @staticmethod
    def _pose(data: mujoco.MjData, body: int) -> rr.Transform3D:
        return rr.Transform3D(translation=data.xpos[body], quaternion=_xyzw(data.xquat[body]))


#: A body is logged again once a coordinate of its position moved this much (m) or a
#: component of its unit quaternion (about half the angle in rad, for small turns).
POSE_MOVED = 1e-3


def _xyzw(wxyz: NDArray[np.float64]) -> rr.Quaternion:
    return rr.Quaternion(xyzw=[float(wxyz[1]), float(wxyz[2]), float(wxyz[3]), float(wxyz[0])])
