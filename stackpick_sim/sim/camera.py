"""Offscreen rendering of the wrist camera: exposure, lens, sensor and light jitter.

Rendering uses MuJoCo's ``Renderer`` (EGL on headless machines: importing ``stackpick_sim``
defaults ``MUJOCO_GL`` to ``egl``). Colour images are RGB uint8
(H, W, 3), row 0 at the top; ``segmentation`` gives per-pixel geom ids of the undistorted
(pinhole) view, the one ground truth is exact in.

A colour frame goes through, each step only when its ``camera`` keys turn it on: the
exposure (motion blur, :mod:`~stackpick_sim.sim.exposure`), the lens
(:mod:`~stackpick_sim.sim.lens`), vignetting, the sensor's photon and read noise with gain
and 8-bit quantisation, the simple Gaussian ``noise_std``, and JPEG
(:mod:`~stackpick_sim.sim.sensor`).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import RenderError
from stackpick_sim.glcheck import gl_failure_message
from stackpick_sim.sim import exposure, lens, sensor
from stackpick_sim.sim.cell import Cell
from stackpick_sim.sim.renderer_pool import active_pool

#: MuJoCo's object type of geoms in a segmentation image, as a plain int.
_GEOM_TYPE = int(mujoco.mjtObj.mjOBJ_GEOM)


def make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A ``mujoco.Renderer``, or a RenderError that names the missing system packages.

    With :func:`~stackpick_sim.sim.renderer_pool.enable_renderer_reuse` on, a pooled one
    (its ``close()`` returns it to the pool).
    """
    pool = active_pool()
    try:
        if pool is not None:
            return pool.acquire(model, height, width)
        return mujoco.Renderer(model, height, width)
    except Exception as exc:  # MuJoCo raises bare RuntimeError/AttributeError/ImportError here
        raise RenderError(gl_failure_message(exc)) from None


class WristCamera:
    """Renders the cell's ``wrist_cam``; build it once per process and reuse it."""

    def __init__(self, cell: Cell) -> None:
        cam = cell.cfg.camera
        self._cell = cell
        # One renderer (one OpenGL context) for colour and segmentation: a second context
        # costs as much as the first, ~0.3 s, for the one or two segmentation frames of an
        # episode.
        # A distorting lens needs a wider pinhole render (same focal length): rendered larger
        # and, for segmentation, cropped back to the camera's own pinhole view.
        self._pad = lens.render_padding(cell.intrinsics)
        self._renderer = make_renderer(cell.model, cam.height + 2 * self._pad,
                                       cam.width + 2 * self._pad)
        self._base_diffuse = cell.model.light_diffuse[cell.ring_light_ids].copy()
        self._fovy = float(cell.model.cam_fovy[cell.camera_id])
        self._padded_fovy = lens.padded_fovy_deg(cell.intrinsics)

    def close(self) -> None:
        """Free the OpenGL contexts."""
        self._renderer.close()

    def _update(self, renderer: mujoco.Renderer) -> None:
        model = self._cell.model
        model.cam_fovy[self._cell.camera_id] = self._padded_fovy if self._pad else self._fovy
        try:
            renderer.update_scene(self._cell.data, camera=self._cell.camera_id)
        finally:
            model.cam_fovy[self._cell.camera_id] = self._fovy
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self._cell.cfg.camera.shadows

    def _crop(self, image: NDArray) -> NDArray:
        p = self._pad
        return image[p:image.shape[0] - p, p:image.shape[1] - p] if p else image

    def _pinhole(self) -> NDArray[np.uint8]:
        self._update(self._renderer)
        return self._renderer.render()

    def _exposed(self) -> NDArray[np.float32]:
        """The (padded) pinhole image integrated over the exposure, float grey levels."""
        cam = self._cell.cfg.camera
        if cam.exposure_s <= 0:
            return self._pinhole().astype(np.float32)
        if cam.blur == "shift":
            shift = exposure.image_shift(self._cell, cam.exposure_s)
            return exposure.smear(self._pinhole().astype(np.float32), shift)
        total: NDArray[np.float32] | None = None
        with exposure.moved(self._cell) as at:
            for tau in exposure.subframe_offsets(cam.exposure_s, cam.blur_subframes):
                at(float(tau))
                frame = self._pinhole().astype(np.float32)
                total = frame if total is None else total + frame
        assert total is not None
        return total / np.float32(cam.blur_subframes)

    def _optics(self) -> NDArray[np.float32]:
        """Exposure, lens and vignetting: the mean image on the sensor, grey levels."""
        image = self._exposed()
        if self._pad:
            image = lens.distort(image, self._cell.intrinsics)
        return sensor.vignette(image, self._cell.cfg.camera.vignetting)

    def _plain(self) -> bool:
        """Whether the frame is a single pinhole render (the optics and sensor models off)."""
        cam = self._cell.cfg.camera
        return (cam.exposure_s <= 0 and not self._pad and cam.vignetting <= 0
                and cam.full_well <= 0)

    def render(self, rng: np.random.Generator | None = None) -> NDArray[np.uint8]:
        """(H, W, 3) RGB uint8 frame of the current state (call mj_forward first).

        With ``rng``, each ring light is scaled by ``1 + N(0, lights.jitter)`` for this frame,
        the sensor's noise is drawn (``camera.full_well > 0``) and Gaussian noise of std
        ``camera.noise_std`` grey levels is added; without it the frame has no noise
        (ground-truth pictures, tests) but keeps its blur, distortion, vignetting and JPEG.
        """
        model = self._cell.model
        ids = self._cell.ring_light_ids
        jitter = self._cell.cfg.lights.jitter
        if rng is not None and jitter > 0:
            scale = np.clip(1.0 + jitter * rng.standard_normal(len(ids)), 0.0, None)
            model.light_diffuse[ids] = self._base_diffuse * scale[:, None]
        try:
            if self._plain():
                image = self._pinhole()
            else:
                signal = self._optics()
                if rng is not None and self._cell.cfg.camera.full_well > 0:
                    signal = sensor.expose(signal, self._cell.cfg.camera, rng)
                image = sensor.quantise(signal)
        finally:
            model.light_diffuse[ids] = self._base_diffuse
        noise_std = self._cell.cfg.camera.noise_std
        if rng is not None and noise_std > 0:
            noisy = image.astype(np.float32)
            noisy += np.float32(noise_std) * rng.standard_normal(image.shape, dtype=np.float32)
            image = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        return sensor.jpeg(image, self._cell.cfg.camera.jpeg_quality)

    def segmentation(self) -> NDArray[np.int32]:
        """(H, W) geom id seen at each pixel, -1 where no geom (background)."""
        self._update(self._renderer)
        self._renderer.enable_segmentation_rendering()
        try:
            seg = self._crop(self._renderer.render())
        finally:
            self._renderer.disable_segmentation_rendering()
        ids = seg[..., 0].astype(np.int32)
        # An int, not the pybind enum: comparing an array with the enum falls back to one
        # Python comparison per pixel (0.2-0.3 s a frame at 320x240, measured).
        ids[seg[..., 1] != _GEOM_TYPE] = -1
        return ids

