"""`render_model`: the copy of a robot's model its camera renders, holding only what its small image needs.

MuJoCo renders on the CPU here (EGL/OSMesa without a GPU: llvmpipe), where the time goes to the shadow map and to
triangles. Measured on 64×64 images (bench/robot_render.py; nao_arm 1.5-2 ms): a URDF model keeps MuJoCo's
default shadow map (4096²) and a shadow-casting light, 10-40 ms of a 30-100 ms image; a humanoid's held body is
~25k triangles in view; a capsule is ~1000 triangles at MuJoCo's default 28 slices.
- Exact (the image does not change): no shadow map and no light casts shadows (the shipped MJCFs already say
  shadowsize="0" and have no lights); a geom of a body welded to the world (the camera is fixed too) whose bounding
  sphere lies outside the camera's view is moved to HIDDEN_GROUP, a group the renderer's default option leaves out.
- A masked camera riding on a link (the record's `masked = true`) draws only its link and the bodies beyond it:
  every other geom is hidden (and the renderer leaves out the skybox), as a segmentation of the hand would give,
  lit by the camera's headlight alone (MASK_LIGHT): its image is then a function of the joints beyond the link only
  (the world's lights would shade the hand by the joints before it).
- File robots only (the shipped robots' images stay those of their stores and models, bit for bit):
  - a held geom farther than FAR_M from everything the arm sweeps (its moving geoms over `poses`) and not in front
    of the arm's image is hidden too: background, such as a humanoid's legs (the torso beside the arm stays);
  - each mesh is simplified by vertex clustering (vertices in one cell of LOD_PX of the pixel footprint at the
    mesh's nearest depth merged, faces that collapse dropped): a humanoid's 24k triangles become 5k;
  - primitives are drawn with SLICES × STACKS facets.
  Measured (bench/robot_render.py, 64×64): TALOS's left arm 103 → 1.8 ms (collision meshes), 155 → 2.5 ms
  (primitives), nao_arm 1.0 ms in the same run; shadows off alone left them at 7-14 ms.
The physics model is never touched: only its copy given to `mujoco.Renderer`.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from bodyschema.datagen.body.kinematics import camera_moves, subtree

HIDDEN_GROUP = 5             # mjvOption shows geom groups 0-2 by default
LOD_PX = 1.0                 # the clustering cell, in pixels at the mesh's nearest depth
SLICES, STACKS = 12, 6       # facets of capsules, cylinders, spheres (MuJoCo: 28 × 16)
MIN_DEPTH = 0.05             # m: a mesh nearer the camera than this is clustered as if here
MASK_LIGHT = (0.3, 0.7)      # a masked camera's headlight: ambient, diffuse (MuJoCo's default: 0.1, 0.4)
FAR_M = 0.15                 # m: a held geom this far from everything the arm sweeps is background (file robots)


def render_model(model: mujoco.MjModel, camera: int, image_size: tuple[int, int], poses: np.ndarray | None,
                 simplify: bool, masked: bool = False) -> mujoco.MjModel:
    """The render copy of `model` for camera `camera`; `poses` (N, nq) rad: where the moving meshes may be (their
    nearest depth sets their detail); `simplify`: the below-a-pixel steps too. A camera that moves with the arm
    (`camera_moves`) hides nothing (every geom may come into its view) but has its meshes simplified alike;
    `masked` (a camera riding on a link): every geom but those of its link and the bodies beyond is hidden."""
    out = copy.copy(model)
    out.vis.quality.shadowsize = 0
    out.light_castshadow[:] = 0
    data = mujoco.MjData(out)
    mujoco.mj_kinematics(out, data)
    mujoco.mj_camlight(out, data)
    moving = camera_moves(out, camera)
    # geoms that keep their depth in every pose: held ones before a fixed camera (none before a moving one)
    static = (out.body_weldid[out.geom_bodyid] == 0) & (not moving)
    depth = _depth(out, data, camera)                     # (ngeom,) m along the view, at qpos0
    hidden = static & _outside(out, data, camera, image_size)
    if masked:
        hidden |= ~subtree(out, int(out.cam_bodyid[camera]))[out.geom_bodyid]
        out.light_active[:] = False
        out.vis.headlight.active = True
        out.vis.headlight.ambient[:], out.vis.headlight.diffuse[:] = MASK_LIGHT[0], MASK_LIGHT[1]
    out.geom_group[hidden] = HIDDEN_GROUP
    if not simplify:
        return out
    out.vis.quality.numslices, out.vis.quality.numstacks = SLICES, STACKS
    nearest = depth - out.geom_rbound
    swept = []                                            # (centre, radius) of the moving geoms at each pose
    for q in [] if poses is None else poses:             # the others: their nearest depth over the poses
        data.qpos[:] = q
        mujoco.mj_kinematics(out, data)
        mujoco.mj_camlight(out, data)
        nearest = np.where(static, nearest, np.minimum(nearest, _depth(out, data, camera) - out.geom_rbound))
        swept.append(data.geom_xpos[~static].copy())
    if swept and not moving:
        hidden |= static & _far(out, data, camera, image_size, np.concatenate(swept), nearest, static)
        out.geom_group[hidden] = HIDDEN_GROUP
    footprint = 2 * np.tan(np.deg2rad(out.cam_fovy[camera]) / 2) / image_size[0]   # m per px per m of depth
    cells: dict[int, float] = {}                         # a mesh shown by several geoms: its finest cell
    for g in np.flatnonzero((out.geom_type == mujoco.mjtGeom.mjGEOM_MESH) & ~hidden):
        mesh = int(out.geom_dataid[g])
        cells[mesh] = min(cells.get(mesh, np.inf), LOD_PX * footprint * max(float(nearest[g]), MIN_DEPTH))
    for mesh, cell in cells.items():
        _cluster(out, mesh, cell)
    return out


def _depth(model, data, camera: int) -> np.ndarray:
    """(ngeom,) m: each geom centre's distance along the camera's view axis (MuJoCo cameras look along −z)."""
    return -(data.geom_xpos - data.cam_xpos[camera]) @ data.cam_xmat[camera].reshape(3, 3)[:, 2]


def _outside(model, data, camera: int, image_size: tuple[int, int]) -> np.ndarray:
    """(ngeom,) bool: the geom's bounding sphere lies wholly outside the camera's view frustum."""
    h, w = image_size
    tan_y = np.tan(np.deg2rad(model.cam_fovy[camera]) / 2)
    tan_x = tan_y * w / h
    local = (data.geom_xpos - data.cam_xpos[camera]) @ data.cam_xmat[camera].reshape(3, 3)   # (ngeom, 3) camera
    sides = np.array([[1, 0, tan_x], [-1, 0, tan_x], [0, 1, tan_y], [0, -1, tan_y]])   # inside: n·p <= 0
    sides = sides / np.linalg.norm(sides, axis=1, keepdims=True)
    radius = model.geom_rbound
    return ((local @ sides.T) > radius[:, None]).any(axis=1) | (local[:, 2] > radius)      # or behind the camera


def _far(model, data, camera: int, image_size: tuple[int, int], arm: np.ndarray, nearest: np.ndarray,
         static: np.ndarray) -> np.ndarray:
    """(ngeom,) bool: a held geom farther than FAR_M from every moving geom centre over the poses (`arm`, (M, 3) m,
    beyond their radii) that does not stand between the camera and the arm's image."""
    radii = np.tile(model.geom_rbound[~static], len(arm) // max(int((~static).sum()), 1))    # (M,) m
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    centres = data.geom_xpos                                                   # held geoms do not move
    gap = (np.sqrt(((centres[:, None, :] - arm[None]) ** 2).sum(-1)) - radii[None]).min(axis=1) - model.geom_rbound
    h, w = image_size
    f = 0.5 * h / np.tan(0.5 * np.deg2rad(model.cam_fovy[camera]))            # px
    local = (centres - data.cam_xpos[camera]) @ data.cam_xmat[camera].reshape(3, 3)
    arm_local = (arm - data.cam_xpos[camera]) @ data.cam_xmat[camera].reshape(3, 3)
    px = f * local[:, :2] / np.maximum(-local[:, 2:], 1e-6)                     # (ngeom, 2) px from the centre
    arm_px = f * arm_local[:, :2] / np.maximum(-arm_local[:, 2:], 1e-6)
    lo, hi = arm_px.min(axis=0), arm_px.max(axis=0)
    reach = f * model.geom_rbound / np.maximum(-local[:, 2], 1e-6)             # px, the bounding sphere's radius
    covers = ((px + reach[:, None] >= lo) & (px - reach[:, None] <= hi)).all(axis=1)
    in_front = nearest < -arm_local[:, 2].max()
    return (gap > FAR_M) & ~(covers & in_front)


def _cluster(model, mesh: int, cell: float) -> None:
    """Vertex clustering in place: the mesh's vertices snapped to their cell's mean, collapsed faces moved past
    the mesh's face count (MuJoCo draws mesh_facenum faces)."""
    v0, nv = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
    f0, nf = model.mesh_faceadr[mesh], model.mesh_facenum[mesh]
    if not np.isfinite(cell) or cell <= 0 or nf < 64:
        return
    verts = model.mesh_vert[v0:v0 + nv]
    _, cluster, counts = np.unique(np.floor(verts / cell).astype(np.int64), axis=0, return_inverse=True,
                                   return_counts=True)
    cluster = cluster.ravel()
    means = np.zeros((len(counts), 3))
    np.add.at(means, cluster, verts)
    verts[:] = means[cluster] / counts[cluster, None]
    faces = model.mesh_face[f0:f0 + nf]
    ids = cluster[faces]                                                    # (nf, 3) cluster of each corner
    keep = (ids[:, 0] != ids[:, 1]) & (ids[:, 1] != ids[:, 2]) & (ids[:, 0] != ids[:, 2])
    _, first = np.unique(np.sort(ids, axis=1)[keep], axis=0, return_index=True)
    kept = np.flatnonzero(keep)[np.sort(first)]                             # one face per cluster triangle
    order = np.concatenate([kept, np.setdiff1d(np.arange(nf), kept)])
    for name in ("mesh_face", "mesh_facenormal", "mesh_facetexcoord"):
        array = getattr(model, name)
        if len(array) >= f0 + nf:
            array[f0:f0 + nf] = array[f0:f0 + nf][order]
    model.mesh_facenum[mesh] = max(len(kept), 1)
