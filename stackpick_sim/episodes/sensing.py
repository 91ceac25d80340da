"""The wrist camera as the controller sees it: frames at a fixed rate, detections that arrive late.

A frame is captured every ``1 / camera.fps`` s of sim time (at the first control tick at or
after its due time). It is rendered (with the scene's pixel noise and light jitter) when the
episode's detector needs the image, and handed to the detector
(:class:`stackpick_sim.pipeline.Detector`) with the phase machine's hints. The detection
becomes usable ``camera.latency_s`` later (the measured vision latency, a constant: the wall
clock never enters an episode). The built-in detectors are in
:mod:`stackpick_sim.episodes.detectors`.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.pipeline import Detector, FaceCandidate, Frame, Hints
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.cell import Cell

FloatArray = NDArray[np.float64]

#: A face seen in a frame (the name the episode modules use).
Candidate = FaceCandidate


@dataclass(frozen=True, kw_only=True)
class Observation:
    """One frame's detections, with the camera pose and time of its capture."""

    capture_time: float
    available_time: float
    world_T_cam: FloatArray
    """(4, 4) camera pose at capture (forward kinematics), OpenCV axes."""
    candidates: tuple[Candidate, ...]
    detection: object
    """The detector's own result (:attr:`stackpick_sim.pipeline.Detections.raw`), or None."""
    image: NDArray[np.uint8] | None
    """The RGB frame, when images are kept (replay) or rendered (``ours``)."""
    reason: str = ""


class Sensor:
    """Captures frames at the camera rate and releases their detections after the latency."""

    def __init__(self, cell: Cell, camera: WristCamera | None, rng: np.random.Generator, *,
                 detector: Detector, keep_images: bool = False) -> None:
        self._cell = cell
        self._camera = camera
        self._rng = rng
        self.detector = detector
        self.keep_images = keep_images
        self.period = 1.0 / cell.cfg.camera.fps
        self.latency = cell.cfg.camera.latency_s
        self._next_capture = 0.0
        self._frame_index = 0
        self._pending: deque[Observation] = deque()
        self.hints = Hints()
        """What the phase machine believes of the tracked face (set before each capture)."""
        self.frames = 0
        self.processed = 0
        """Frames rendered and run through the detector."""
        self.process = True
        """Whether the next frame is processed; the phase logic clears it for frames the
        controller would not use (after the servo, or with the tracked face out of view)."""
        self.wall = {"render": 0.0, "vision": 0.0}
        self.last: Observation | None = None
        """The latest frame captured (its detection may not be usable yet)."""

    def due(self, t: float) -> bool:
        """Whether a frame is due at sim time ``t`` s."""
        return t >= self._next_capture - 1e-9

    def _render(self, rng: np.random.Generator | None) -> NDArray[np.uint8]:
        if self._camera is None:
            raise EpisodeError("rendering needs a WristCamera")
        return self._camera.render(rng)

    def capture(self, t: float, world_T_cam: FloatArray) -> None:
        """Capture a frame now (state after mj_forward) and queue its detection."""
        self._frame_index += 1
        self._next_capture = self._frame_index * self.period
        self.frames += 1
        image = None
        if not self.process:
            if self.keep_images:  # replay: a clean picture, the noise stream left untouched
                image = self._render(None)
            self._queue(Observation(
                capture_time=t, available_time=t + self.latency, world_T_cam=world_T_cam.copy(),
                candidates=(), detection=None, image=image,
                reason="not processed: the controller does not use this frame"))
            return
        self.processed += 1
        if self.detector.needs_image or self.keep_images:
            start = time.perf_counter()
            image = self._render(self._rng)
            self.wall["render"] += time.perf_counter() - start
        frame = Frame(image=image if self.detector.needs_image else None,
                      intrinsics=self._cell.intrinsics, world_T_cam=world_T_cam.copy(), time=t)
        start = time.perf_counter()
        found = self.detector.detect(frame, self.hints)
        self.wall["vision"] += time.perf_counter() - start
        self._queue(Observation(
            capture_time=t, available_time=t + self.latency, world_T_cam=world_T_cam.copy(),
            candidates=tuple(found.candidates), detection=found.raw,
            image=image if self.keep_images else None, reason=found.reason))

    def _queue(self, obs: Observation) -> None:
        self._pending.append(obs)
        self.last = obs

    def ready(self, t: float) -> list[Observation]:
        """Observations whose detection is usable at sim time ``t`` s, oldest first."""
        out = []
        while self._pending and self._pending[0].available_time <= t + 1e-9:
            out.append(self._pending.popleft())
        return out


def ellipse_inside(e: Ellipse, k: CameraIntrinsics, margin_px: float = 0.0) -> bool:
    """Whether the whole ellipse lies inside the image, ``margin_px`` px from its border."""
    u0, v0, u1, v1 = e.bounds()
    return (u0 >= margin_px and v0 >= margin_px and u1 <= k.width - 1 - margin_px
            and v1 <= k.height - 1 - margin_px)


def angle_deg(a: FloatArray, b: FloatArray) -> float:
    """Angle between two vectors, degrees."""
    c = float(a @ b) / (float(np.linalg.norm(a)) * float(np.linalg.norm(b)))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))
