"""Reuse of offscreen renderers across the cells of many episodes in one process.

Every seed builds its own cell (its own ``MjModel``: the number and kinds of cylinders
differ), and a ``mujoco.Renderer`` is tied to the model it was made for. Building one costs
about 0.3 s on this project's 2-core machines (measured: the ``MjrContext`` uploads the
model's textures and builtin geoms, about 0.13 s; the 10000-geom ``MjvScene`` 0.03-0.08 s;
the first frame compiles shaders, about 0.05 s), once or twice per episode (colour, and
segmentation where ground truth needs it), against about 0.02 s per frame afterwards.

What a rendering context holds from the model is its *render assets*: textures, materials
with textures, meshes, height fields, skins, flexes, plane geoms, the offscreen buffer's
size and the quality settings. Two models with identical render assets can share one
context, which is what the pool does: it fingerprints those assets, hands out a free
renderer of the same fingerprint and size if there is one (patching the few context fields
that follow ``stat.extent`` and ``vis``), and takes it back on ``close()``. Images are bit
for bit those of a fresh renderer (``tests/test_runs_renderer_pool.py``).

Off by default; :func:`enable_renderer_reuse` turns it on for the calling process (the
episode runner's worker processes do).
"""

from __future__ import annotations

import hashlib
from typing import Any

import mujoco
import numpy as np

#: Renderers kept per (fingerprint, size) when returned; more are freed. Two are in use per
#: episode (colour and segmentation).
MAX_FREE_PER_KEY = 2
#: Distinct fingerprints kept; the least recently used one is freed past this.
MAX_KEYS = 8


def render_asset_fingerprint(model: mujoco.MjModel) -> str:
    """Hex digest of everything ``mjr_makeContext`` uploads from ``model`` (see module doc)."""
    h = hashlib.sha1(usedforsecurity=False)
    plane = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    parts: list[Any] = [
        model.mat_texid, model.mat_texuniform, model.mat_texrepeat,
        model.tex_type, model.tex_height, model.tex_width, model.tex_nchannel, model.tex_data,
        model.mesh_vert, model.mesh_normal, model.mesh_face, model.mesh_texcoord,
        model.mesh_vertadr, model.mesh_faceadr,
        model.hfield_size, model.hfield_nrow, model.hfield_ncol, model.hfield_data,
        np.flatnonzero(plane), model.geom_size[plane],
        np.array([model.nskin, model.nflex, model.nmat, model.ntex, model.nmesh,
                  model.vis.global_.offwidth, model.vis.global_.offheight,
                  model.vis.quality.shadowsize, model.vis.quality.offsamples,
                  model.vis.quality.numslices, model.vis.quality.numstacks,
                  model.vis.quality.numquads]),
    ]
    for p in parts:
        a = np.ascontiguousarray(p)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


class PooledRenderer(mujoco.Renderer):
    """A ``mujoco.Renderer`` that can be pointed at another model with the same render assets.

    ``close()`` gives it back to its pool instead of freeing its contexts.
    """

    def __init__(self, pool: RendererPool, key: tuple[str, int, int], model: mujoco.MjModel,
                 height: int, width: int) -> None:
        super().__init__(model, height, width)
        self._pool = pool
        self._key = key
        self._default_flags = self.scene.flags.copy()

    def retarget(self, model: mujoco.MjModel) -> None:
        """Render ``model`` from now on (same fingerprint); reset modes and scene flags."""
        # The parent's private state: the model read by update_scene and the modes.
        self._model = model
        self._scene_option = mujoco.MjvOption()
        self._segmentation_rendering = False
        self._depth_rendering = False
        self.scene.flags[:] = self._default_flags
        ctx = self._mjr_context
        if ctx is None:
            raise RuntimeError("a closed renderer cannot be reused")
        # The context fields that mjr_makeContext derives from stat.extent and vis.
        extent = float(model.stat.extent)
        ctx.shadowClip = extent * float(model.vis.map.shadowclip)
        ctx.shadowScale = float(model.vis.map.shadowscale)
        ctx.fogStart = extent * float(model.vis.map.fogstart)
        ctx.fogEnd = extent * float(model.vis.map.fogend)
        ctx.fogRGBA[:] = model.vis.rgba.fog
        ctx.lineWidth = float(model.vis.global_.linewidth)

    def close(self) -> None:
        """Return to the pool (the contexts stay alive for the next model)."""
        self._pool.release(self)

    def free(self) -> None:
        """Really free the OpenGL contexts."""
        super().close()


class RendererPool:
    """Free renderers by (render-asset fingerprint, height, width)."""

    def __init__(self) -> None:
        self._free: dict[tuple[str, int, int], list[PooledRenderer]] = {}
        self.built = 0
        """Renderers constructed so far."""
        self.reused = 0
        """Renderers handed out again."""

    def acquire(self, model: mujoco.MjModel, height: int, width: int) -> PooledRenderer:
        """A renderer for ``model``: a free one of the same assets and size, or a new one."""
        key = (render_asset_fingerprint(model), height, width)
        free = self._free.get(key)
        if free:
            renderer = free.pop()
            renderer.retarget(model)
            self.reused += 1
            return renderer
        self.built += 1
        return PooledRenderer(self, key, model, height, width)

    def release(self, renderer: PooledRenderer) -> None:
        """Keep ``renderer`` for reuse (or free it when enough of its kind are kept)."""
        key = renderer._key
        free = self._free.pop(key, [])
        self._free[key] = free  # most recently used last
        if len(free) >= MAX_FREE_PER_KEY:
            renderer.free()
        else:
            free.append(renderer)
        while len(self._free) > MAX_KEYS:
            oldest = next(iter(self._free))
            for r in self._free.pop(oldest):
                r.free()

    def clear(self) -> None:
        """Free every kept renderer."""
        for free in self._free.values():
            for r in free:
                r.free()
        self._free.clear()


_POOL: RendererPool | None = None


def enable_renderer_reuse() -> RendererPool:
    """Turn renderer reuse on in this process (idempotent); returns the process's pool."""
    global _POOL
    if _POOL is None:
        _POOL = RendererPool()
    return _POOL


def active_pool() -> RendererPool | None:
    """The process's pool, or None while reuse is off."""
    return _POOL
