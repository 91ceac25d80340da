"""``stackpick detect IMAGE.png [--scene S] [--set K=V] [--json] [--overlay OUT.png]``: top
object and its pose."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.loader import available_scenes, load_scene
from stackpick_sim.episodes.detectors import scene_detector_config
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import FOVY_RANGE_DEG, CameraIntrinsics, check_fovy, face_depth_range
from stackpick_sim.image_io import read_image, write_image
from stackpick_sim.overlay import detection_overlay
from stackpick_sim.vision.detection import DetectedEllipse, Detection
from stackpick_sim.vision.detector import (
    DEFAULT_FOVY_DEG,
    DEFAULT_RADII_M,
    DetectorConfig,
    detect,
)
from stackpick_sim.vision.edges import as_rgb_or_gray
from stackpick_sim.vision.ellipses import find_ellipses


def register(subparsers: Any) -> None:
    """Add the ``detect`` subcommand."""
    p = subparsers.add_parser("detect", help="find the top cylinder and its pose in an image",
                              description=__doc__)
    p.add_argument("image", help="image file: PNG, JPEG, TIFF, BMP, ... (colour or grey, 8 or "
                   "16 bit or float, at most 4096 x 4096 px)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("--overlay", metavar="OUT.png", help="write the detections drawn on the image "
                   "(format from the extension: .png, .jpg, .bmp, .tif, .webp)")
    p.add_argument("--scene", metavar="NAME_OR_PATH",
                   help="take the camera's field of view and lens distortion, the object kinds "
                   "(radii, colours, heights), the top face's depth range at the look pose "
                   "and the [vision] settings from this scene "
                   f"({', '.join(available_scenes())} or a .toml file); the options below "
                   "override them")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="KEY=VALUE", help="override a scene key (implies --scene paper "
                   "when --scene is not given), e.g. --set vision.max_arcs=12")
    p.add_argument("--fovy", type=float, default=None,
                   help="vertical field of view of a centred pinhole camera, deg, "
                   f"{FOVY_RANGE_DEG[0]:g} to {FOVY_RANGE_DEG[1]:g} (default: the scene's, "
                   f"else {DEFAULT_FOVY_DEG:g})")
    p.add_argument("--radii", type=float, nargs="+", default=None, metavar="M",
                   help=f"candidate face radii, metres, {RADIUS_RANGE_M[0]:g} to "
                   f"{RADIUS_RANGE_M[1]:g} (default: the scene's kinds, else "
                   f"{' '.join(f'{r:g}' for r in DEFAULT_RADII_M)})")
    p.add_argument("--depth-range", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help=f"expected depth of the top face, metres, {DEPTH_RANGE_M[0]:g} to "
                   f"{DEPTH_RANGE_M[1]:g} (chooses the radius; default: the scene's look "
                   "pose, else none)")
    p.add_argument("--ellipses-only", action="store_true",
                   help="report the ellipses alone, each with its outline support (no top "
                   "object, no pose): stackpick_sim.vision.find_ellipses")
    p.add_argument("--min-axis", type=float, default=5.0, metavar="PX",
                   help="with --ellipses-only: smallest semi-minor axis, px (default 5)")
    p.add_argument("--max-axis", type=float, default=None, metavar="PX",
                   help="with --ellipses-only: largest semi-major axis, px (default: none)")
    p.add_argument("--min-support", type=float, default=0.6, metavar="SHARE",
                   help="with --ellipses-only: smallest share of the outline with a "
                   "consistent edge along it, 0-1 (default 0.6)")
    p.set_defaults(func=run)


#: Face radii --radii accepts, m: from a 1 mm part to a 1 m drum, what suction picks.
RADIUS_RANGE_M = (0.001, 1.0)
#: Face depths --depth-range accepts, m: from a camera 1 cm above the face to one 10 m away.
DEPTH_RANGE_M = (0.01, 10.0)


def _check_ellipse_bounds(args: argparse.Namespace) -> None:
    """ConfigError naming the allowed range for a --min-axis, --max-axis or --min-support
    value outside it."""
    if not (math.isfinite(args.min_axis) and args.min_axis >= 0):
        raise ConfigError(f"--min-axis {args.min_axis!r} is out of range; allowed: >= 0 px")
    if args.max_axis is not None and not (math.isfinite(args.max_axis) and args.max_axis > 0):
        raise ConfigError(f"--max-axis {args.max_axis!r} is out of range; allowed: > 0 px")
    if not 0.0 <= args.min_support <= 1.0:
        raise ConfigError(f"--min-support {args.min_support!r} is out of range; allowed: 0 to 1")


def _check_ranges(args: argparse.Namespace) -> None:
    """ConfigError naming the allowed range for a --fovy, --radii or --depth-range value
    outside it (before the image is read)."""
    if args.fovy is not None:
        check_fovy(args.fovy)
    lo, hi = RADIUS_RANGE_M
    for r in args.radii or ():
        if not (math.isfinite(r) and lo <= r <= hi):
            raise ConfigError(f"--radii {r!r} is out of range; allowed: {lo:g} to {hi:g} m")
    _check_ellipse_bounds(args)
    if args.depth_range is not None:
        lo, hi = DEPTH_RANGE_M
        near, far = args.depth_range
        if not all(math.isfinite(d) and lo <= d <= hi for d in args.depth_range) or near > far:
            raise ConfigError(f"--depth-range {near!r} {far!r} is out of range; allowed: "
                              f"MIN <= MAX, each {lo:g} to {hi:g} m")


def draw_overlay(image: NDArray, detection: Detection,
                 intrinsics: CameraIntrinsics | None) -> NDArray[np.uint8]:
    """BGR picture (twice the image's size) of the detections of an RGB/grey image (any
    dtype the detector takes, scaled to 8 bits the same way): labelled ellipses (top in
    green), the top face's pose and a legend."""
    return detection_overlay(as_rgb_or_gray(image), detection, intrinsics)


def detector_config(args: argparse.Namespace, width: int, height: int) -> DetectorConfig:
    """The detector's settings for a ``width`` x ``height`` image from ``--scene``/``--set``
    (when given) and the explicit options, which take precedence."""
    if args.scene is not None or args.overrides:
        scene = load_scene(args.scene or "paper", args.overrides)
        fovy = scene.camera.fovy_deg if args.fovy is None else args.fovy
        config = scene_detector_config(
            scene, CameraIntrinsics.from_fovy(fovy, width, height, scene.camera.distortion),
            face_depth_range(scene.camera.look_height, scene.objects.max_face_height))
    else:
        fovy = DEFAULT_FOVY_DEG if args.fovy is None else args.fovy
        config = DetectorConfig(intrinsics=CameraIntrinsics.from_fovy(fovy, width, height),
                                radii_m=DEFAULT_RADII_M)
    if args.radii is not None:  # other radii: the scene's colours and heights no longer apply
        config = replace(config, radii_m=tuple(args.radii), kind_colours=None, heights_m=None)
    if args.depth_range:
        config = replace(config, depth_range_m=tuple(args.depth_range))
    return config


def _ellipses_only(image: NDArray[np.uint8], config: DetectorConfig,
                   args: argparse.Namespace) -> int:
    """``--ellipses-only``: print the scored ellipses (text or JSON); exit 0."""
    found = find_ellipses(image, min_axis_px=args.min_axis, max_axis_px=args.max_axis,
                          min_support=args.min_support, limits=config.limits,
                          params=config.ellipses)
    if args.overlay:
        shown = Detection(ellipses=tuple(
            DetectedEllipse(ellipse=s.ellipse, segments=(), residual_px=s.residual_px,
                            support=s.support) for s in found))
        write_image(args.overlay, draw_overlay(image, shown, None), order="bgr")
    if args.json:
        print(json.dumps(finite_json({"ellipses": [s.as_dict() for s in found]}), indent=2,
                         allow_nan=False))
        return 0
    print(f"{len(found)} ellipses")
    for i, s in enumerate(found):
        e = s.ellipse
        print(f"  [{i}] centre ({e.cx:.1f}, {e.cy:.1f}) axes {e.a:.1f} x {e.b:.1f} px "
              f"angle {e.angle_deg:.1f} deg support {s.support:.2f}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Run the detector on one image; print text or JSON; exit 0 (also on a miss)."""
    _check_ranges(args)
    image = read_image(args.image)
    h, w = image.shape[:2]
    config = detector_config(args, w, h)
    if args.ellipses_only:
        return _ellipses_only(image, config, args)
    detection = detect(image, config)
    if args.overlay:
        write_image(args.overlay, draw_overlay(image, detection, config.intrinsics), order="bgr")
    if args.json:
        print(json.dumps(finite_json(detection.as_dict()), indent=2, allow_nan=False))
        return 0
    print(f"{len(detection.ellipses)} ellipses")
    for i, det in enumerate(detection.ellipses):
        e = det.ellipse
        mark = "  <- top" if i == detection.top else ""
        print(f"  [{i}] centre ({e.cx:.1f}, {e.cy:.1f}) axes {e.a:.1f} x {e.b:.1f} px "
              f"angle {e.angle_deg:.1f} deg support {det.support:.2f}{mark}")
    if detection.pose is not None:
        p = detection.pose
        print(f"pose: x {p.x:.2f} px, y {p.y:.2f} px, theta_x {p.theta_x_deg:.2f} deg, "
              f"theta_y {p.theta_y_deg:.2f} deg, depth {p.depth_m:.3f} m (radius {p.radius_m} m)")
    else:
        print(f"no top object: {detection.reason}")
    timing = ", ".join(f"{k} {v:.2f}" for k, v in detection.timings_ms.items())
    print(f"timings (ms): {timing}")
    return 0


def finite_json(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (JSON has no NaN/Infinity)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(v) for v in value]
    return value
