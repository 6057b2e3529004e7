"""`visual = "primitives"`: a URDF's meshes replaced by capsules and boxes sized from its links (no mesh file read).

A URDF whose meshes are not on disk (ROS `package://` meshes often live in another package) or not in a format
MuJoCo loads still has its kinematics and inertias. `strip_meshes` removes every mesh geometry (visual and
collision) from the URDF before MuJoCo reads it and says which; `add_primitives` then gives each link that lost
its visuals:
- a capsule from the link's origin (its joint) to each child joint origin farther than MIN_SEGMENT, of radius
  √(2·I_axis/m) (a solid cylinder's moment about its axis is m·r²/2; I_axis = dᵀ·I·d about the link's centre of
  mass along the segment d), clipped to RADIUS;
- a link with no such segment (a hand, a tool, a foot): the box of its principal inertias at its centre of mass
  (a box of sides a, b, c has I_a = m·(b² + c²)/12, so a² = 6·(I_b + I_c − I_a)/m), half-sides clipped to HALF_SIDE;
  a link without mass: a sphere of SPHERE_RADIUS at its origin.
The primitives are visual only (they collide with nothing) and light grey, so the arm stands out at 64 px.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np

MIN_SEGMENT = 0.01           # m: a child joint closer to the link's origin than this gets no capsule
RADIUS = (0.01, 0.08)        # m: capsule radius bounds (a 7-joint arm's links are 3-8 cm thick)
HALF_SIDE = (0.01, 0.12)     # m: box half-side bounds
SPHERE_RADIUS = 0.02         # m: a link without mass or segment (a frame that showed a mesh)
RGBA = (0.75, 0.75, 0.75, 1.0)


def strip_meshes(root: ET.Element) -> dict[str, list[str]]:
    """Remove every <visual>/<collision> with a mesh from the URDF `root`; {link: [mesh file as written, ...]} of
    the links that lost a visual this way and have none left (those get primitives)."""
    replaced: dict[str, list[str]] = {}
    for link in root.iter("link"):
        lost = []
        for kind in ("visual", "collision"):
            for element in link.findall(kind):
                meshes = [m.get("filename", "") for m in element.iter("mesh")]
                if meshes:
                    link.remove(element)
                    lost += meshes if kind == "visual" else []
        if lost and link.find("visual") is None:
            replaced[link.get("name", "")] = lost
    return replaced


def add_primitives(spec: mujoco.MjSpec, links: list[str]) -> None:
    """Capsules and boxes (see the module docstring) on the spec's bodies named in `links`."""
    for name in links:
        body = spec.body(name)
        if body is None:
            continue
        mass, com, inertia = _inertia(body)
        segments = [np.array(child.pos, float) for child in body.bodies
                    if np.linalg.norm(child.pos) > MIN_SEGMENT]
        for end in segments:
            d = end / np.linalg.norm(end)
            axial = float(d @ inertia @ d)
            radius = np.sqrt(2 * axial / mass) if mass > 0 and axial > 0 else RADIUS[0] * 2
            _geom(body, mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, *end],
                  size=[float(np.clip(radius, *RADIUS)), 0, 0])
        if segments:
            continue
        if mass <= 0:
            _geom(body, mujoco.mjtGeom.mjGEOM_SPHERE, pos=[0, 0, 0], size=[SPHERE_RADIUS, 0, 0])
            continue
        moments, axes = np.linalg.eigh(inertia)                      # principal moments, axes as columns
        if np.linalg.det(axes) < 0:
            axes[:, 0] = -axes[:, 0]
        sides = np.sqrt(np.maximum(6 * (moments.sum() - 2 * moments) / mass, 0.0)) / 2
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, axes.ravel())
        _geom(body, mujoco.mjtGeom.mjGEOM_BOX, pos=list(com), quat=list(quat), size=list(np.clip(sides, *HALF_SIDE)))


def _geom(body, kind, **attrs) -> None:
    body.add_geom(type=kind, rgba=list(RGBA), contype=0, conaffinity=0, group=1, **attrs)


def _inertia(body) -> tuple[float, np.ndarray, np.ndarray]:
    """(kg, centre of mass (3,) m, inertia (3, 3) kg·m² about it) in the body's frame, from the URDF's <inertial>."""
    mass = float(body.mass) if body.explicitinertial else 0.0
    com = np.nan_to_num(np.array(body.ipos, float))
    full = np.array(body.fullinertia, float)
    if np.isfinite(full).all() and full[:3].any():
        xx, yy, zz, xy, xz, yz = full
        tensor = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    else:
        tensor = np.diag(np.nan_to_num(np.array(body.inertia, float)))
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, np.asarray(body.iquat, float) / np.linalg.norm(body.iquat))
    rot = rot.reshape(3, 3)
    return mass, com, rot @ tensor @ rot.T
