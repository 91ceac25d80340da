"""The replay video: H.264 frames of the wrist camera beside an outside view of the pile.

Each frame has a banner (seed, sim time, phase, the episode's outcome), the wrist camera's
latest frame with the detections and the tracker's estimate drawn (and, optionally, the true
top faces), and an outside camera that follows the pile along the belt. The file is H.264
(yuv420p, even frame sizes, ``+faststart``), which browsers and code hosts play, written
through imageio-ffmpeg (the optional extra ``stackpick-sim[video]``, which ships ffmpeg).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.episodes.episode import TickInfo
from stackpick_sim.episodes.record import EpisodeRecord
from stackpick_sim.episodes.sensing import Observation
from stackpick_sim.exceptions import EpisodeError
from stackpick_sim.geometry import Ellipse
from stackpick_sim.overlay import (
    OTHER_COLOUR,
    TOP_COLOUR,
    TRUTH_COLOUR,
    draw_ellipse,
    draw_marker,
    draw_text,
    scale_ellipse,
)
from stackpick_sim.sim.camera import WristCamera, make_renderer
from stackpick_sim.sim.cell import Cell
from stackpick_sim.sim.ground_truth import frame_truth

#: Both views are shown at this size, px (width, height): twice the wrist camera's 320x240.
VIEW_SIZE = (640, 480)
#: Height of the banner above the views, px (even, as H.264's 4:2:0 sampling needs).
BANNER_HEIGHT = 64
#: Height of the legend strip below the views, px (even).
LEGEND_HEIGHT = 32
#: Seconds the last frame is held with the replay's outcome at the end of the video.
HOLD_END_S = 1.5
#: The outside camera: distance from the pile's centre, m; azimuth and elevation, deg
#: (MuJoCo's free-camera convention); vertical field of view follows the renderer's model.
OUTSIDE_DISTANCE = 0.6
OUTSIDE_AZIMUTH_DEG = 150.0
OUTSIDE_ELEVATION_DEG = -28.0
#: Height above the pile's centre the outside camera aims at, m: the tool above it in view.
OUTSIDE_AIM_UP = 0.12
#: Colour of the tracker's estimate, BGR.
ESTIMATE_COLOUR = (255, 80, 255)
#: Banner colours, BGR: background, text, success, failure.
BANNER_BG = (40, 40, 40)
BANNER_TEXT = (235, 235, 235)
SUCCESS_TEXT = (110, 220, 110)
FAILURE_TEXT = (90, 110, 255)
#: Constant rate factor of the H.264 encoder (lower: better quality, larger file).
CRF = 23


def frame_size() -> tuple[int, int]:
    """(width, height) of the video's frames, px: both views, the banner and the legend."""
    return 2 * VIEW_SIZE[0], BANNER_HEIGHT + VIEW_SIZE[1] + LEGEND_HEIGHT


def outcome_text(record: EpisodeRecord | dict[str, Any] | None) -> str:
    """"success" or e.g. "lift timeout: target toppled" (reason, then detail)."""
    if record is None:
        return "outcome not recorded"
    get = record.get if isinstance(record, dict) else lambda k, d=None: getattr(record, k, d)
    if get("success"):
        return "success"
    reason = str(get("failure") or "failure").replace("_", " ")
    detail = str(get("failure_detail") or "")
    return f"{reason}: {detail}" if detail else reason


class H264Writer:
    """Writes RGB frames of one size into an H.264 (yuv420p) .mp4 with imageio-ffmpeg."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float) -> None:
        try:
            import imageio_ffmpeg
        except ImportError:
            raise EpisodeError("replay --video needs imageio-ffmpeg: pip install "
                               "'stackpick-sim[video]'") from None
        width, height = size
        if width % 2 or height % 2:
            raise ValueError(f"H.264 yuv420p needs even frame sizes, got {width}x{height}")
        self.path = path
        self.size = size
        self.frames = 0
        self._gen = imageio_ffmpeg.write_frames(
            str(path), size, fps=fps, codec="libx264", pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p", macro_block_size=2, ffmpeg_log_level="error",
            output_params=["-crf", str(CRF), "-movflags", "+faststart"])
        try:
            self._gen.send(None)  # starts ffmpeg
        except (OSError, RuntimeError) as exc:
            raise EpisodeError(f"cannot write the video {path}: {exc}") from None

    def write(self, frame_bgr: NDArray[np.uint8]) -> None:
        """Append one (H, W, 3) BGR frame of the writer's size."""
        h, w = frame_bgr.shape[:2]
        if (w, h) != self.size:
            raise ValueError(f"frame {w}x{h} != video {self.size[0]}x{self.size[1]}")
        self._gen.send(np.ascontiguousarray(frame_bgr[..., ::-1]))
        self.frames += 1

    def close(self) -> None:
        """Finish the file."""
        self._gen.close()

    def __enter__(self) -> H264Writer:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class OutsideView:
    """A free camera that follows the pile's centre along the belt, the tool above in view."""

    def __init__(self, cell: Cell) -> None:
        self._cell = cell
        self._renderer = make_renderer(cell.model, VIEW_SIZE[1], VIEW_SIZE[0])
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self._camera.distance = OUTSIDE_DISTANCE
        self._camera.azimuth = OUTSIDE_AZIMUTH_DEG
        self._camera.elevation = OUTSIDE_ELEVATION_DEG

    def render(self) -> NDArray[np.uint8]:
        """(H, W, 3) BGR picture of the current state."""
        data = self._cell.data
        centre = np.mean([data.xpos[o.body_id] for o in self._cell.objects], axis=0)
        self._camera.lookat[:] = centre + np.array([0.0, 0.0, OUTSIDE_AIM_UP])
        self._renderer.update_scene(data, camera=self._camera)
        return np.ascontiguousarray(self._renderer.render()[..., ::-1])

    def close(self) -> None:
        """Free the OpenGL context."""
        self._renderer.close()


class ReplayFilm:
    """Composes the video's frames from the episode's ticks and writes them.

    ``recorded`` is the run's record of the seed (its outcome is shown in the banner from the
    first frame); ``show_truth`` draws the true top faces (ground truth at each capture).
    """

    def __init__(self, cell: Cell, writer: H264Writer, *, seed: int,
                 recorded: EpisodeRecord | dict[str, Any] | None, show_truth: bool = False) -> None:
        self._cell = cell
        self._writer = writer
        self._seed = seed
        self._outcome = outcome_text(recorded) if recorded is not None else None
        self._show_truth = show_truth
        self._wrist = WristCamera(cell)
        self._outside = OutsideView(cell)
        self._latest: Observation | None = None
        self._truth: dict[float, list[Ellipse]] = {}
        self._captures = 0
        self._last_frame: NDArray[np.uint8] | None = None
        self._last_info: tuple[float, str] = (0.0, "")

    def close(self) -> None:
        """Free the renderers."""
        self._wrist.close()
        self._outside.close()

    def on_tick(self, info: TickInfo, draw: bool) -> None:
        """Take the tick's observations; write a frame when ``draw``."""
        sensor = info.episode.sensor
        if self._show_truth and sensor.frames != self._captures:
            # A frame was captured at this tick, in this very state: its truth is this one.
            truth = frame_truth(self._cell, self._wrist.segmentation())
            self._truth[round(info.time, 6)] = [o.ellipse for o in truth.objects
                                                if o.is_top and o.ellipse is not None]
        self._captures = sensor.frames
        for obs in info.observations:
            self._latest = obs
        if draw:
            self._last_info = (info.time, info.phase)
            frame = self._compose(self._wrist_view(info), self._outside.render(),
                                  info.time, info.phase, self._outcome)
            self._last_frame = frame
            self._writer.write(frame)

    def finish(self, record: EpisodeRecord, fps: float) -> None:
        """Hold the last frame for :data:`HOLD_END_S` with the replay's own outcome."""
        if self._last_frame is None:
            return
        t, phase = self._last_info
        views = self._last_frame[BANNER_HEIGHT:BANNER_HEIGHT + VIEW_SIZE[1]]
        frame = self._compose(views[:, :VIEW_SIZE[0]], views[:, VIEW_SIZE[0]:], t, phase,
                              outcome_text(record), final=True)
        for _ in range(max(1, round(HOLD_END_S * fps))):
            self._writer.write(frame)

    def _wrist_view(self, info: TickInfo) -> NDArray[np.uint8]:
        h = VIEW_SIZE[1]
        obs = self._latest
        if obs is None or obs.image is None:
            # No frame captured yet (the arm moving to the look pose): the camera live.
            live = cv2.resize(self._wrist.render()[..., ::-1], VIEW_SIZE,
                              interpolation=cv2.INTER_NEAREST)
            out = np.ascontiguousarray(live, dtype=np.uint8)
            draw_text(out, "live view: no frame captured yet", (10, h - 14), BANNER_TEXT, 0.55)
            return out
        return wrist_view(obs, info, self._truth.get(round(obs.capture_time, 6), []))

    def _compose(self, wrist: NDArray[np.uint8], outside: NDArray[np.uint8], t: float,
                 phase: str, outcome: str | None, final: bool = False) -> NDArray[np.uint8]:
        w, h = VIEW_SIZE
        frame = np.zeros((BANNER_HEIGHT + h + LEGEND_HEIGHT, 2 * w, 3), np.uint8)
        frame[:BANNER_HEIGHT] = BANNER_BG
        frame[BANNER_HEIGHT:BANNER_HEIGHT + h, :w] = wrist
        frame[BANNER_HEIGHT:BANNER_HEIGHT + h, w:] = outside
        frame[BANNER_HEIGHT + h:] = BANNER_BG
        head = f"seed {self._seed}    t = {t:5.2f} s    phase: {phase}"
        draw_text(frame, head, (12, 26), BANNER_TEXT, 0.7)
        if outcome is not None:
            label = "replay outcome: " if final else "recorded outcome: "
            colour = SUCCESS_TEXT if outcome == "success" else FAILURE_TEXT
            draw_text(frame, label + outcome, (12, 54), colour, 0.6)
        legend = ("wrist camera: green detected top, orange other detections, magenta + "
                  "tracker estimate" + (", cyan dashes true top" if self._show_truth else "")
                  + "    |    outside view following the pile")
        draw_text(frame, legend, (12, BANNER_HEIGHT + h + 21), BANNER_TEXT, 0.45)
        return frame


def wrist_view(obs: Observation, info: TickInfo,
               truth: Sequence[Ellipse] = ()) -> NDArray[np.uint8]:
    """(VIEW_SIZE) BGR view of ``obs``'s wrist frame (it must hold an image): its candidates
    (green the top, orange the others), the ``truth`` ellipses dashed, the tracker's estimate
    at the capture time (a magenta cross) and the capture time."""
    assert obs.image is not None, "wrist_view needs an observation with its image"
    w, h = VIEW_SIZE
    k = w / obs.image.shape[1]
    out = np.ascontiguousarray(cv2.resize(obs.image[..., ::-1], VIEW_SIZE,
                                          interpolation=cv2.INTER_NEAREST), dtype=np.uint8)
    for cand in obs.candidates:
        if cand.ellipse is not None:
            draw_ellipse(out, scale_ellipse(cand.ellipse, k),
                         TOP_COLOUR if cand.is_top else OTHER_COLOUR, 3)
    for ellipse in truth:
        draw_ellipse(out, scale_ellipse(ellipse, k), TRUTH_COLOUR, 2, halo=False,
                     dashed=True)
    est = info.episode.estimator
    if est.initialised:
        state = est.state(obs.capture_time, obs.world_T_cam)
        r, p = obs.world_T_cam[:3, :3], obs.world_T_cam[:3, 3]
        c = r.T @ (state.centre - p)
        if c[2] > 1e-3:
            u, v = info.episode.scene.cell.intrinsics.project(c)[0]
            draw_marker(out, ((u + 0.5) * k - 0.5, (v + 0.5) * k - 0.5), ESTIMATE_COLOUR,
                        18, 2)
    draw_text(out, f"frame at t = {obs.capture_time:.2f} s", (10, h - 14), BANNER_TEXT, 0.55)
    return out
