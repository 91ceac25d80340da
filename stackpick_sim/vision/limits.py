"""Bounds on the detector's work, so that any image returns within a fixed time and memory.

The ellipse stages cost about linearly in the edge pixels, but the merge, the top rule and
its last-resort arc pairs cost about quadratically in the chains, fits and arcs they compare:
on textures, glyphs and hundreds of small ellipses those counts are ten to a hundred times a
pile's, and the pairings ran for seconds. Two kinds of bound keep every input's cost fixed:

- **Work caps** (:class:`WorkLimits`): beyond a pixel count the image is downscaled by an
  integer factor (ellipses and pose mapped back to the full image); beyond a count of chains,
  fits, ellipses or arcs, only the longest (or best-supported) go on. Caps are deterministic:
  the same image gives the same result on any machine and under any load, as seeded episodes
  require. The defaults lie well above what a pile's frames need (measured on fresh paper
  frames: at most 23 chains, 12 fits, 12 ellipses and 7 arcs in the ROI of a 320x240 frame),
  so they change nothing there.
- **A time budget** (``time_budget_ms``, off by default): checked between stages; when it runs
  out the detector returns a falsy :class:`~stackpick_sim.vision.detection.Detection` whose
  reason names the stage. It depends on the machine's load, so a result under a budget is not
  reproducible: for real-time use, not for seeded runs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import VisionCfg
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse


@dataclass(frozen=True, kw_only=True)
class WorkLimits:
    """Caps on the detector's work (see the module docstring); the fields, units and
    defaults are those of the scene's ``[vision]`` table
    (:class:`~stackpick_sim.config.scene_config.VisionCfg`), except that no time budget is
    None here.

    ``max_pixels`` (px): larger images are downscaled by the smallest integer factor that
    brings them within it. ``max_chains``: connected edge pieces linked and edge chains kept,
    longest first. ``max_fits``:
    segment fits passed to the merge, longest arcs first. ``max_ellipses``: merged ellipses
    passed to the refit and the top rule, best-supported first. ``max_arcs``: arcs the
    last-resort arc pairs are drawn from, longest first. ``max_refits``: ellipses the top
    rule's contrast retry refits, best-supported first (each reads profiles along its whole
    outline: ~3 ms for a 100 px face). ``time_budget_ms`` (ms of wall-clock time, None: no
    budget): see the module docstring.
    """

    max_pixels: int = VisionCfg.max_pixels
    max_chains: int = VisionCfg.max_chains
    max_fits: int = VisionCfg.max_fits
    max_ellipses: int = VisionCfg.max_ellipses
    max_arcs: int = VisionCfg.max_arcs
    max_refits: int = VisionCfg.max_refits
    time_budget_ms: float | None = None

    def __post_init__(self) -> None:
        for name in ("max_pixels", "max_chains", "max_fits", "max_ellipses", "max_arcs",
                     "max_refits"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"limits.{name} must be a positive integer, got {value!r}")
        if self.time_budget_ms is not None and not self.time_budget_ms > 0:
            raise ConfigError("limits.time_budget_ms must be positive milliseconds or None, "
                              f"got {self.time_budget_ms!r}")

    @classmethod
    def of(cls, cfg: VisionCfg) -> WorkLimits:
        """The limits a scene's ``[vision]`` table sets."""
        return cls(max_pixels=cfg.max_pixels, max_chains=cfg.max_chains, max_fits=cfg.max_fits,
                   max_ellipses=cfg.max_ellipses, max_arcs=cfg.max_arcs,
                   max_refits=cfg.max_refits,
                   time_budget_ms=cfg.time_budget_ms if cfg.time_budget_ms > 0 else None)


class Deadline:
    """The wall-clock end of a time budget (never, without one)."""

    def __init__(self, start: float, budget_ms: float | None) -> None:
        self.budget_ms = budget_ms
        self.end = math.inf if budget_ms is None else start + budget_ms / 1e3

    def expired(self) -> bool:
        """Whether the budget has run out."""
        return self.end != math.inf and time.perf_counter() > self.end


def downscale_factor(shape: tuple[int, int], max_pixels: int) -> int:
    """The smallest integer factor f with (H // f) * (W // f) <= ``max_pixels``."""
    h, w = shape
    f = max(1, math.ceil(math.sqrt(h * w / max_pixels)))
    while (h // f) * (w // f) > max_pixels:
        f += 1
    return f


def downscaled(image: NDArray[np.uint8], factor: int) -> NDArray[np.uint8]:
    """``image`` averaged over ``factor`` x ``factor`` blocks (its bottom and right rows that
    do not fill a block dropped): pixel j of the result covers pixels j f ... j f + f - 1."""
    h, w = image.shape[0] // factor, image.shape[1] // factor
    crop = np.ascontiguousarray(image[:h * factor, :w * factor])
    return np.asarray(cv2.resize(crop, (w, h), interpolation=cv2.INTER_AREA), np.uint8)


def scaled_intrinsics(k: CameraIntrinsics, factor: int) -> CameraIntrinsics:
    """The intrinsics of the :func:`downscaled` image: a full-image point u lies at
    (u - (f - 1) / 2) / f."""
    shift = (factor - 1) / 2.0
    return CameraIntrinsics(fx=k.fx / factor, fy=k.fy / factor, cx=(k.cx - shift) / factor,
                            cy=(k.cy - shift) / factor, width=k.width // factor,
                            height=k.height // factor)


def upscaled(ellipse: Ellipse, factor: int) -> Ellipse:
    """An ellipse of the :func:`downscaled` image in the full image's pixels."""
    shift = (factor - 1) / 2.0
    return Ellipse.of(ellipse.cx * factor + shift, ellipse.cy * factor + shift,
                      ellipse.a * factor, ellipse.b * factor, ellipse.angle_deg)


def longest(items: Sequence[NDArray], cap: int) -> list[int]:
    """Indices of the ``cap`` longest arrays of ``items`` (first axis; of equals, the first),
    in their order: all of them when there are at most ``cap``."""
    if len(items) <= cap:
        return list(range(len(items)))
    order = sorted(range(len(items)), key=lambda i: (-items[i].shape[0], i))
    return sorted(order[:cap])
