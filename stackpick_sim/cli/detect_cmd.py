"""``stackpick detect IMAGE.png [--scene S] [--set K=V] [--json] [--overlay OUT.png]``: top
object and its pose."""

from __future__ import annotations

import argparse
import json
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.loader import available_scenes, load_scene
from stackpick_sim.exceptions import ImageError
from stackpick_sim.geometry import CameraIntrinsics, face_depth_range
from stackpick_sim.vision.detection import DetectedEllipse, Detection
from stackpick_sim.vision.detector import (
    DEFAULT_FOVY_DEG,
    DEFAULT_RADII_M,
    DetectorConfig,
    detect,
    object_kinds,
)
from stackpick_sim.vision.ellipses import find_ellipses
from stackpick_sim.vision.limits import WorkLimits


def register(subparsers: Any) -> None:
    """Add the ``detect`` subcommand."""
    p = subparsers.add_parser("detect", help="find the top cylinder and its pose in an image",
                              description=__doc__)
    p.add_argument("image", help="PNG/JPEG image (colour or grey)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("--overlay", metavar="OUT.png", help="write the detections drawn on the image")
    p.add_argument("--scene", metavar="NAME_OR_PATH",
                   help="take the camera's field of view, the object kinds (radii, colours, "
                   "heights), the top face's depth range at the look pose and the [vision] "
                   f"limits from this scene ({', '.join(available_scenes())} or a .toml "
                   "file); the options below override them")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="KEY=VALUE", help="override a scene key (implies --scene paper "
                   "when --scene is not given), e.g. --set vision.max_arcs=12")
    p.add_argument("--fovy", type=float, default=None,
                   help="vertical field of view of a centred pinhole camera, deg (default: "
                   f"the scene's, else {DEFAULT_FOVY_DEG:g})")
    p.add_argument("--radii", type=float, nargs="+", default=None, metavar="M",
                   help="candidate face radii, metres (default: the scene's kinds, else "
                   f"{' '.join(f'{r:g}' for r in DEFAULT_RADII_M)})")
    p.add_argument("--depth-range", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="expected depth of the top face, metres (chooses the radius; "
                   "default: the scene's look pose, else none)")
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


def _read(path: str) -> NDArray[np.uint8]:
    """Image file as (H, W) grey or (H, W, 3) RGB uint8; ImageError if unreadable."""
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"cannot read image '{path}' (missing or not an image file)")
    if img.ndim == 3 and img.shape[2] >= 3:
        img = cv2.cvtColor(img[:, :, :3], cv2.COLOR_BGR2RGB)
    return np.asarray(img)


def draw_overlay(image: NDArray[np.uint8], detection: Detection) -> NDArray[np.uint8]:
    """(H, W, 3) BGR copy of an RGB/grey image with ellipses (top in green) and pose drawn."""
    out = image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    out = cv2.cvtColor(out[:, :, :3].astype(np.uint8), cv2.COLOR_RGB2BGR)
    for i, det in enumerate(detection.ellipses):
        e = det.ellipse
        colour = (0, 255, 0) if i == detection.top else (0, 0, 255)
        cv2.ellipse(out, ((e.cx, e.cy), (2 * e.a, 2 * e.b), e.angle_deg), colour, 1,
                    cv2.LINE_AA)
    if detection.pose is not None:
        p = detection.pose
        cv2.drawMarker(out, (round(p.x), round(p.y)), (0, 255, 0), cv2.MARKER_CROSS, 8, 1)
    return np.asarray(out, np.uint8)


def detector_config(args: argparse.Namespace, width: int, height: int) -> DetectorConfig:
    """The detector's settings for a ``width`` x ``height`` image from ``--scene``/``--set``
    (when given) and the explicit options, which take precedence."""
    fovy, radii = DEFAULT_FOVY_DEG, DEFAULT_RADII_M
    colours: tuple[tuple[float, float, float], ...] | None = None
    heights: tuple[float, ...] | None = None
    depth: tuple[float, float] | None = None
    limits = WorkLimits()
    if args.scene is not None or args.overrides:
        scene = load_scene(args.scene or "paper", args.overrides)
        fovy = scene.camera.fovy_deg
        kinds = [(t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
                 for name, t in scene.object_types.items() if name in scene.objects.types]
        radii, colours, heights = object_kinds(kinds)
        depth = face_depth_range(scene.camera.look_height, scene.objects.max_face_height)
        limits = WorkLimits.of(scene.vision)
    if args.radii is not None:  # other radii: the scene's colours and heights no longer apply
        radii, colours, heights = tuple(args.radii), None, None
    return DetectorConfig(
        intrinsics=CameraIntrinsics.from_fovy(fovy if args.fovy is None else args.fovy,
                                              width, height),
        radii_m=radii, kind_colours=colours, heights_m=heights,
        depth_range_m=tuple(args.depth_range) if args.depth_range else depth, limits=limits)


def _ellipses_only(image: NDArray[np.uint8], config: DetectorConfig,
                   args: argparse.Namespace) -> int:
    """``--ellipses-only``: print the scored ellipses (text or JSON); exit 0."""
    found = find_ellipses(image, min_axis_px=args.min_axis, max_axis_px=args.max_axis,
                          min_support=args.min_support, limits=config.limits)
    if args.overlay:
        shown = Detection(ellipses=tuple(
            DetectedEllipse(ellipse=s.ellipse, segments=(), residual_px=s.residual_px,
                            support=s.support) for s in found))
        if not cv2.imwrite(args.overlay, draw_overlay(image, shown)):
            raise ImageError(f"cannot write overlay '{args.overlay}'")
    if args.json:
        print(json.dumps({"ellipses": [s.as_dict() for s in found]}, indent=2))
        return 0
    print(f"{len(found)} ellipses")
    for i, s in enumerate(found):
        e = s.ellipse
        print(f"  [{i}] centre ({e.cx:.1f}, {e.cy:.1f}) axes {e.a:.1f} x {e.b:.1f} px "
              f"angle {e.angle_deg:.1f} deg support {s.support:.2f}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Run the detector on one image; print text or JSON; exit 0 (also on a miss)."""
    image = _read(args.image)
    h, w = image.shape[:2]
    config = detector_config(args, w, h)
    if args.ellipses_only:
        return _ellipses_only(image, config, args)
    detection = detect(image, config)
    if args.overlay:
        if not cv2.imwrite(args.overlay, draw_overlay(image, detection)):
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
