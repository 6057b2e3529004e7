"""A robot's images: the offscreen GL renderer of its fixed camera, and the offscreen buffer its model gets.

`Robot` creates a `CameraRenderer` on its first render, so a robot is cheap to build in a worker process and the GL
context belongs to the process that renders (it is never pickled). The renderer draws a copy of the model made for
its camera (`render_scope.render_model`: what the camera cannot tell apart simplified, files not shipped only).
"""

from __future__ import annotations

import cv2
import mujoco
import numpy as np

from bodyschema.datagen.body.render_scope import render_model

OFFSCREEN = 1024               # px: the offscreen buffer a model gets when its file asks for less
RENDER_POSES = 64              # poses (seed 0) over which the renderer's copy finds the moving meshes' nearest depth


class CameraRenderer:
    """One GL renderer looking through a fixed camera of `model`, at images of `image_size` (H, W) px."""

    def __init__(self, model: mujoco.MjModel, camera_id: int, image_size: tuple[int, int], channels: int,
                 full_ranges: np.ndarray, simplify: bool, masked: bool = False):
        """full_ranges: (Dq, 2) rad, the joint box the scene's copy is fitted over; simplify, masked: see
        render_model (a masked camera's background is black: no skybox either)."""
        h, w = image_size
        poses = np.random.default_rng(0).uniform(full_ranges[:, 0], full_ranges[:, 1], (RENDER_POSES, len(full_ranges)))
        scene = render_model(model, camera_id, image_size, poses, simplify=simplify, masked=masked)
        self.renderer = mujoco.Renderer(scene, height=h, width=w)
        if masked:
            self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self.camera.fixedcamid = camera_id
        self.rgb_buf = np.empty((h, w, 3), dtype=np.uint8)
        self.image_size = (h, w)
        self.channels = channels

    def render(self, model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray) -> np.ndarray:
        """(N, Dq) rad, set on `data` pose by pose → (N, H, W) uint8 grayscale or (N, H, W, 3) uint8 RGB."""
        h, w = self.image_size
        qpos = data.qpos
        images = np.empty((q.shape[0], h, w, 3) if self.channels == 3 else (q.shape[0], h, w), dtype=np.uint8)
        for q_i, image_i in zip(q, images):
            qpos[:] = q_i
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            self.renderer.update_scene(data, self.camera)
            if self.channels == 3:
                self.renderer.render(out=image_i)
            else:                                         # ITU-R BT.601 luma, as cv2
                cv2.cvtColor(self.renderer.render(out=self.rgb_buf), cv2.COLOR_RGB2GRAY, dst=image_i)
        return images

    def close(self) -> None:
        """Free the GL context."""
        self.renderer.close()


def fit_offscreen(model: mujoco.MjModel, image_size: tuple[int, int]) -> None:
    """A model file that asks for a small offscreen buffer (URDF: none) gets one the image fits in."""
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), OFFSCREEN, image_size[1])
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), OFFSCREEN, image_size[0])
