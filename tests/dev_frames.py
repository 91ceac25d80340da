"""Pinned rendered development frames of the cluttered and grey scenes (PNG and ground-truth
JSON as `stackpick dataset` writes them), loaded with their scene's object kinds."""

from __future__ import annotations

from pathlib import Path

from stackpick_sim.config.loader import load_scene
from stackpick_sim.geometry import CameraIntrinsics, mask_iou
from stackpick_sim.vision.benchmark.frames import BenchFrame, load_frame
from stackpick_sim.vision.detector import DetectorConfig, TopObjectDetector

DATA = Path(__file__).parent / "data" / "cluttered_dev_frames"
GREY_DATA = Path(__file__).parent / "data" / "grey_dev_frames"
#: The paper scene with both kinds light grey.
GREY = ("object_types.large.rgba=[0.7,0.7,0.7,1.0]", "object_types.small.rgba=[0.7,0.7,0.7,1.0]")
K = CameraIntrinsics.from_fovy(45.0, 320, 240)


def dev_frame(seed: int, directory: Path = DATA, scene: str = "cluttered",
              overrides: tuple[str, ...] = ()) -> BenchFrame:
    """The frame of ``seed`` in ``directory``, with the kinds of ``scene`` (``overrides``
    applied)."""
    cfg = load_scene(scene, overrides)
    kinds = tuple((t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
                  for t in cfg.object_types.values())
    return load_frame(directory, seed, cfg.conveyor.top_z, cfg.objects.max_face_height, kinds)


def top_iou(frame: BenchFrame, config: DetectorConfig) -> float:
    """The best overlap (IoU) of the top face detected with ``config`` in ``frame`` with
    one of its true top faces (a top face must be found)."""
    found = TopObjectDetector(config).detect(frame.image_rgb).top_ellipse
    assert found is not None
    return max(mask_iou(found, f.ellipse, frame.shape) for f in frame.tops)
