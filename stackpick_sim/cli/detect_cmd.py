"""``stackpick detect IMAGE.png [--json] [--overlay OUT.png]``: top object and its pose."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import FOVY_RANGE_DEG, CameraIntrinsics, check_fovy
from stackpick_sim.image_io import read_image, write_image
from stackpick_sim.overlay import detection_overlay
from stackpick_sim.vision.detection import Detection
from stackpick_sim.vision.detector import (
    DEFAULT_FOVY_DEG,
    DEFAULT_RADII_M,
    DetectorConfig,
    detect,
)
from stackpick_sim.vision.edges import as_rgb_or_gray


def register(subparsers: Any) -> None:
    """Add the ``detect`` subcommand."""
    p = subparsers.add_parser("detect", help="find the top cylinder and its pose in an image",
                              description=__doc__)
    p.add_argument("image", help="image file: PNG, JPEG, TIFF, BMP, ... (colour or grey, 8 or "
                   "16 bit or float, at most 4096 x 4096 px)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("--overlay", metavar="OUT.png", help="write the detections drawn on the image "
                   "(format from the extension: .png, .jpg, .bmp, .tif, .webp)")
    p.add_argument("--fovy", type=float, default=DEFAULT_FOVY_DEG,
                   help="vertical field of view of a centred pinhole camera, deg, "
                   f"{FOVY_RANGE_DEG[0]:g} to {FOVY_RANGE_DEG[1]:g} (default 45)")
    p.add_argument("--radii", type=float, nargs="+", default=list(DEFAULT_RADII_M),
                   metavar="M", help="candidate face radii, metres, "
                   f"{RADIUS_RANGE_M[0]:g} to {RADIUS_RANGE_M[1]:g} (default 0.035 0.025)")
    p.add_argument("--depth-range", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="expected depth of the top face, metres, "
                   f"{DEPTH_RANGE_M[0]:g} to {DEPTH_RANGE_M[1]:g} (chooses the radius)")
    p.set_defaults(func=run)


#: Face radii --radii accepts, m: from a 1 mm part to a 1 m drum, what suction picks.
RADIUS_RANGE_M = (0.001, 1.0)
#: Face depths --depth-range accepts, m: from a camera 1 cm above the face to one 10 m away.
DEPTH_RANGE_M = (0.01, 10.0)


def _check_ranges(args: argparse.Namespace) -> None:
    """ConfigError naming the allowed range for a --fovy, --radii or --depth-range value
    outside it (before the image is read)."""
    check_fovy(args.fovy)
    lo, hi = RADIUS_RANGE_M
    for r in args.radii:
        if not (math.isfinite(r) and lo <= r <= hi):
            raise ConfigError(f"--radii {r!r} is out of range; allowed: {lo:g} to {hi:g} m")
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


def run(args: argparse.Namespace) -> int:
    """Run the detector on one image; print text or JSON; exit 0 (also on a miss)."""
    _check_ranges(args)
    image = read_image(args.image)
    h, w = image.shape[:2]
    config = DetectorConfig(intrinsics=CameraIntrinsics.from_fovy(args.fovy, w, h),
                            radii_m=tuple(args.radii),
                            depth_range_m=tuple(args.depth_range) if args.depth_range else None)
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
