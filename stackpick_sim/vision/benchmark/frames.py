"""Benchmark input: camera frames with their ground truth, from a data set or the simulator.

A data set directory is what ``stackpick dataset`` writes: ``<seed:06d>.png`` (BGR PNG of the
wrist camera) and ``<seed:06d>.json`` (the :class:`~stackpick_sim.sim.ground_truth.FrameTruth`
schema). Frames generated in-process go through the same JSON-shaped dict, so both sources
give identical :class:`BenchFrame` objects.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import ImageError, SceneGenerationError
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, face_depth_range
from stackpick_sim.image_io import read_image

#: A scene's object kinds: (radius m, (r, g, b) 0-1, height m) per kind.
Kinds = tuple[tuple[float, tuple[float, float, float], float], ...]


@dataclass(frozen=True, kw_only=True)
class TruthFace:
    """Ground truth of one cylinder's camera-facing face (pixels, degrees)."""

    name: str
    radius_m: float
    ellipse: Ellipse | None
    face_center_px: tuple[float, float]
    theta_x_deg: float
    theta_y_deg: float
    visible_fraction: float
    is_top: bool


@dataclass(frozen=True, kw_only=True)
class BenchFrame:
    """One frame: ``image_rgb`` (H, W, 3) uint8 RGB, intrinsics, the depth range a caller knows
    (metres along the optical axis, from the camera height above the belt), the faces, and the
    scene's object kinds as (radius m, (r, g, b) 0-1, height m) triples (a caller knows those
    too; empty when unknown)."""

    seed: int
    image_rgb: NDArray[np.uint8]
    intrinsics: CameraIntrinsics
    depth_range_m: tuple[float, float]
    faces: tuple[TruthFace, ...]
    kinds: Kinds = ()

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return int(self.image_rgb.shape[0]), int(self.image_rgb.shape[1])

    @property
    def tops(self) -> list[TruthFace]:
        """The true top objects' faces."""
        return [f for f in self.faces if f.is_top and f.ellipse is not None]


def frame_from_record(seed: int, image_rgb: NDArray[np.uint8], record: dict[str, Any],
                      belt_top_z: float, max_face_height: float,
                      kinds: Kinds = ()
                      ) -> BenchFrame:
    """A BenchFrame from an RGB image and a ground-truth dict (FrameTruth JSON schema); the
    depth range is :func:`~stackpick_sim.geometry.face_depth_range` of the camera's height
    above the belt (``belt_top_z``, m) and the scene's ``max_face_height`` (m)."""
    k = record["intrinsics"]
    intr = CameraIntrinsics(fx=k["fx"], fy=k["fy"], cx=k["cx"], cy=k["cy"],
                            width=int(record["width"]), height=int(record["height"]),
                            dist=tuple(record.get("distortion", (0.0,) * 5)))
    faces = []
    for o in record["objects"]:
        e = o["ellipse"]
        faces.append(TruthFace(
            name=o["name"], radius_m=float(o["radius"]),
            ellipse=None if e is None else Ellipse(**e),
            face_center_px=(float(o["face_center_px"][0]), float(o["face_center_px"][1])),
            theta_x_deg=float(o["theta_x_deg"]), theta_y_deg=float(o["theta_y_deg"]),
            visible_fraction=float(o["visible_fraction"]), is_top=bool(o["is_top"])))
    camera_height = float(record["world_T_cam"][2][3]) - belt_top_z
    rng = face_depth_range(camera_height, max_face_height)
    return BenchFrame(seed=seed, image_rgb=image_rgb, intrinsics=intr, depth_range_m=rng,
                      faces=tuple(faces), kinds=kinds)


def dataset_seeds(directory: Path) -> list[int]:
    """Seeds of the frames present in a data set directory, ascending."""
    return sorted(int(p.stem) for p in directory.glob("*.json") if p.stem.isdigit())


def load_frame(directory: Path, seed: int, belt_top_z: float, max_face_height: float,
               kinds: Kinds = ()
               ) -> BenchFrame:
    """Read frame ``seed`` of a data set directory; ImageError if its files are missing."""
    stem = directory / f"{seed:06d}"
    if not (Path(f"{stem}.png").exists() and Path(f"{stem}.json").exists()):
        raise ImageError(f"frame {seed} missing in {directory} (need {stem}.png and .json)")
    image = read_image(f"{stem}.png")
    record = json.loads(Path(f"{stem}.json").read_text())
    rgb = image if image.ndim == 3 else np.ascontiguousarray(np.dstack([image] * 3))
    return frame_from_record(seed, rgb, record, belt_top_z, max_face_height, kinds)


def _kinds(types: dict[str, Any]) -> Kinds:
    """(radius, rgb, height) per object type of a scene's ``object_types`` table (JSON-shaped
    or ObjectType)."""
    out = []
    for t in types.values():
        rgba = t["rgba"] if isinstance(t, dict) else t.rgba
        radius = t["radius"] if isinstance(t, dict) else t.radius
        height = t["height"] if isinstance(t, dict) else t.height
        out.append((float(radius), (float(rgba[0]), float(rgba[1]), float(rgba[2])),
                    float(height)))
    return tuple(out)


def _recorded_scene(directory: Path) -> dict[str, Any]:
    """The scene config recorded in a data set's index.json (JSON-shaped), {} if absent."""
    index = directory / "index.json"
    if not index.exists():
        return {}
    scene = json.loads(index.read_text()).get("scene", {})
    return scene if isinstance(scene, dict) else {}


def _scene_kinds(scene: dict[str, Any]) -> Kinds:
    types = scene.get("object_types", {})
    return _kinds(types) if isinstance(types, dict) else ()


def dataset_kinds(directory: Path) -> Kinds:
    """Object kinds (radius, rgb, height) recorded in a data set's index.json; () if absent."""
    return _scene_kinds(_recorded_scene(directory))


def iter_dataset(directory: Path, seeds: Sequence[int] | None,
                 cfg: SceneConfig) -> Iterator[BenchFrame]:
    """Frames of a data set directory (all present, or the given seeds that are present).

    The object kinds, belt height and ``objects.max_face_height`` come from the scene
    recorded in the data set's index.json, else from ``cfg`` (a directory without an index:
    without the kinds the detector would know no face radius or colour)."""
    present = dataset_seeds(directory)
    have = set(present)
    wanted = present if seeds is None else [s for s in seeds if s in have]
    scene = _recorded_scene(directory)
    kinds = _scene_kinds(scene) if scene else _kinds(dict(cfg.object_types))
    belt_top_z = float(scene.get("conveyor", {}).get("top_z", cfg.conveyor.top_z))
    max_face_height = float(scene.get("objects", {}).get("max_face_height",
                                                          cfg.objects.max_face_height))
    for seed in wanted:
        yield load_frame(directory, seed, belt_top_z, max_face_height, kinds)


def iter_generated(cfg: SceneConfig, seeds: Sequence[int]) -> Iterator[BenchFrame]:
    """Frames rendered by the simulator for each seed (seeds whose pile fails are skipped)."""
    from stackpick_sim.sim.snapshot import seeded_look_frame  # heavy (MuJoCo): only here

    for seed in seeds:
        try:
            _, image, truth = seeded_look_frame(cfg, seed)
        except SceneGenerationError:
            continue
        yield frame_from_record(seed, image, truth.as_dict(), cfg.conveyor.top_z,
                                cfg.objects.max_face_height,
                                _kinds(dict(cfg.object_types)))
