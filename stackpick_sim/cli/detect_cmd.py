"""``stackpick detect IMAGE.png [--json] [--overlay OUT.png]``: top object and its pose."""

from __future__ import annotations

import argparse
import json
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ImageError
from stackpick_sim.geometry import CameraIntrinsics
from stackpick_sim.overlay import detection_overlay
from stackpick_sim.vision.detection import Detection
from stackpick_sim.vision.detector import (
    DEFAULT_FOVY_DEG,
    DEFAULT_RADII_M,
    DetectorConfig,
    detect,
)


def register(subparsers: Any) -> None:
    """Add the ``detect`` subcommand."""
    p = subparsers.add_parser("detect", help="find the top cylinder and its pose in an image",
                              description=__doc__)
    p.add_argument("image", help="PNG/JPEG image (colour or grey)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("--overlay", metavar="OUT.png", help="write the detections drawn on the image")
    p.add_argument("--fovy", type=float, default=DEFAULT_FOVY_DEG,
                   help="vertical field of view of a centred pinhole camera, deg (default 45)")
    p.add_argument("--radii", type=float, nargs="+", default=list(DEFAULT_RADII_M),
                   metavar="M", help="candidate face radii, metres (default 0.035 0.025)")
    p.add_argument("--depth-range", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="expected depth of the top face, metres (chooses the radius)")
    p.set_defaults(func=run)


def _read(path: str) -> NDArray[np.uint8]:
    """Image file as (H, W) grey or (H, W, 3) RGB uint8; ImageError if unreadable."""
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"cannot read image '{path}' (missing or not an image file)")
    if img.ndim == 3 and img.shape[2] >= 3:
        img = cv2.cvtColor(img[:, :, :3], cv2.COLOR_BGR2RGB)
    return np.asarray(img)


def draw_overlay(image: NDArray[np.uint8], detection: Detection,
                 intrinsics: CameraIntrinsics | None) -> NDArray[np.uint8]:
    """BGR picture (twice the image's size) of the detections: labelled ellipses (top in
    green), the top face's pose and a legend."""
    return detection_overlay(image, detection, intrinsics)


def run(args: argparse.Namespace) -> int:
    """Run the detector on one image; print text or JSON; exit 0 (also on a miss)."""
    image = _read(args.image)
    h, w = image.shape[:2]
    config = DetectorConfig(intrinsics=CameraIntrinsics.from_fovy(args.fovy, w, h),
                            radii_m=tuple(args.radii),
                            depth_range_m=tuple(args.depth_range) if args.depth_range else None)
    detection = detect(image, config)
    if args.overlay:
        if not cv2.imwrite(args.overlay, draw_overlay(image, detection, config.intrinsics)):
            raise ImageError(f"cannot write overlay '{args.overlay}'")
    if args.json:
        print(json.dumps(detection.as_dict(), indent=2))
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
