"""Pictures for people: ellipses, labels, poses and legends drawn over camera frames.

Every outline and every text is drawn over a dark halo, so it reads on any object colour, on
the belt and on the background alike. Labels are placed where they overlap neither each other
nor the image border (:func:`place_labels`). Frames are enlarged (nearest neighbour) before
drawing so that thin outlines and text stay readable on a 320x240 camera.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import CameraIntrinsics, Ellipse

if TYPE_CHECKING:
    from stackpick_sim.sim.ground_truth import FrameTruth
    from stackpick_sim.vision.detection import Detection

#: Drawing colours, BGR (OpenCV's order): a top object, any other object, a true top face
#: drawn over detections, the pose's normal arrow.
TOP_COLOUR = (60, 230, 60)
OTHER_COLOUR = (40, 170, 255)
TRUTH_COLOUR = (255, 230, 40)
NORMAL_COLOUR = (255, 255, 255)
#: Colour of the halo under every outline and text.
HALO_COLOUR = (0, 0, 0)
#: Sub-pixel precision of drawn outlines: coordinates are scaled by 2**SHIFT.
SHIFT = 4
#: Font and default text scale (OpenCV's Hershey simplex: about 22 px per unit of scale).
FONT = cv2.FONT_HERSHEY_SIMPLEX
LABEL_SCALE = 0.45
#: Overlays are drawn on the frame enlarged by this factor.
OVERLAY_SCALE = 2
#: Length of the drawn face normal, as a multiple of the face's radius.
NORMAL_LENGTH = 1.5


def scale_ellipse(ellipse: Ellipse, k: float) -> Ellipse:
    """``ellipse`` in an image enlarged ``k`` times (pixel centres stay pixel centres)."""
    return type(ellipse)(cx=(ellipse.cx + 0.5) * k - 0.5, cy=(ellipse.cy + 0.5) * k - 0.5,
                         a=ellipse.a * k, b=ellipse.b * k, angle_deg=ellipse.angle_deg)


def scale_point(uv: Sequence[float], k: float) -> tuple[float, float]:
    """Pixel ``uv`` in an image enlarged ``k`` times."""
    return (uv[0] + 0.5) * k - 0.5, (uv[1] + 0.5) * k - 0.5


def draw_ellipse(image: NDArray[np.uint8], ellipse: Ellipse, colour: tuple[int, int, int],
                 thickness: int = 1, halo: bool = True, dashed: bool = False) -> None:
    """Draw ``ellipse``'s outline (over a dark halo unless not ``halo``; in 36 dashes when
    ``dashed``, to show over another outline) into the BGR ``image`` in place, with sub-pixel
    accuracy."""
    pts = np.round(ellipse.points(180) * (1 << SHIFT)).astype(np.int32)
    parts = [pts[i:i + 6] for i in range(0, len(pts), 10)] if dashed else [pts]
    strokes = ((HALO_COLOUR, thickness + 2), (colour, thickness))
    for col, th in strokes if halo else strokes[1:]:
        cv2.polylines(image, parts, isClosed=not dashed, color=col, thickness=th,
                      lineType=cv2.LINE_AA, shift=SHIFT)


def draw_marker(image: NDArray[np.uint8], uv: tuple[float, float], colour: tuple[int, int, int],
                size: int = 10, thickness: int = 1) -> None:
    """A cross at pixel ``uv`` (u, v) over a dark halo."""
    at = (round(uv[0]), round(uv[1]))
    for col, th in ((HALO_COLOUR, thickness + 2), (colour, thickness)):
        cv2.drawMarker(image, at, col, cv2.MARKER_CROSS, size, th, cv2.LINE_AA)


def draw_arrow(image: NDArray[np.uint8], start: tuple[float, float], end: tuple[float, float],
               colour: tuple[int, int, int]) -> None:
    """An arrow from ``start`` to ``end`` (pixels) over a dark halo."""
    a, b = (round(start[0]), round(start[1])), (round(end[0]), round(end[1]))
    for col, th in ((HALO_COLOUR, 4), (colour, 2)):
        cv2.arrowedLine(image, a, b, col, th, cv2.LINE_AA, tipLength=0.25)


def text_size(text: str, scale: float = LABEL_SCALE) -> tuple[int, int]:
    """(width, height) of ``text`` in px, descenders and halo included."""
    (w, h), base = cv2.getTextSize(text, FONT, scale, 1)
    return w + 6, h + base + 4


def draw_text(image: NDArray[np.uint8], text: str, org: tuple[float, float],
              colour: tuple[int, int, int], scale: float = LABEL_SCALE) -> None:
    """Text with its baseline's left end at ``org``, over a dark halo (the same glyphs shifted
    one pixel each way: a thicker stroke would advance the glyphs differently)."""
    x, y = round(org[0]), round(org[1])
    weight = 2 if scale >= 0.6 else 1
    for dx, dy in ((-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)):
        cv2.putText(image, text, (x + dx, y + dy), FONT, scale, HALO_COLOUR, weight, cv2.LINE_AA)
    cv2.putText(image, text, (x, y), FONT, scale, colour, weight, cv2.LINE_AA)


def draw_label(image: NDArray[np.uint8], text: str, uv: tuple[float, float],
               colour: tuple[int, int, int]) -> None:
    """Label text at pixel ``uv`` (its baseline's left end), readable on any background."""
    draw_text(image, text, uv, colour)


@dataclass(frozen=True)
class Label:
    """A label to place near an ellipse: its text, colour and the ellipse."""

    text: str
    colour: tuple[int, int, int]
    ellipse: Ellipse


def _overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> int:
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return max(0, w) * max(0, h)


def place_labels(labels: Sequence[Label], size: tuple[int, int],
                 blocked: Sequence[tuple[int, int, int, int]] = ()
                 ) -> list[tuple[int, int, int, int]]:
    """Boxes (x0, y0, x1, y1) for ``labels`` in an image of ``size`` (width, height): beside
    its ellipse (above, below, right, left, then further out), inside the image, overlapping
    no other label nor the ``blocked`` boxes (a legend); the least overlapping place when
    every place overlaps."""
    width, height = size
    placed: list[tuple[int, int, int, int]] = list(blocked)
    boxes = []
    for label in labels:
        w, h = text_size(label.text)
        e = label.ellipse
        x0, y0, x1, y1 = e.bounds()
        spots = []
        for gap in (3, 3 + h, 3 + 2 * h):
            spots += [(e.cx - w / 2, y0 - gap - h), (e.cx - w / 2, y1 + gap),
                      (x1 + gap, e.cy - h / 2), (x0 - gap - w, e.cy - h / 2)]
        best: tuple[int, tuple[int, int, int, int]] | None = None
        for sx, sy in spots:
            bx = int(min(max(sx, 0), width - w))
            by = int(min(max(sy, 0), height - h))
            box = (bx, by, bx + w, by + h)
            cost = sum(_overlap(box, p) for p in placed)
            if best is None or cost < best[0]:
                best = (cost, box)
            if cost == 0:
                break
        assert best is not None
        placed.append(best[1])
        boxes.append(best[1])
    return boxes


def _darken(image: NDArray[np.uint8], box: tuple[int, int, int, int], keep: float) -> None:
    """Darken ``box`` (x0, y0, x1, y1) of ``image`` to ``keep`` of its brightness."""
    x0, y0, x1, y1 = box
    region = image[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)]
    region[:] = (keep * region.astype(np.float32)).astype(np.uint8)


def draw_labels(image: NDArray[np.uint8], labels: Sequence[Label],
                blocked: Sequence[tuple[int, int, int, int]] = ()) -> None:
    """Draw ``labels`` on darkened boxes where :func:`place_labels` puts them."""
    h, w = image.shape[:2]
    for label, box in zip(labels, place_labels(labels, (w, h), blocked), strict=True):
        base = cv2.getTextSize(label.text, FONT, LABEL_SCALE, 1)[1]
        _darken(image, box, 0.3)
        draw_text(image, label.text, (box[0] + 3, box[3] - base - 2), label.colour)


def with_legend(image: NDArray[np.uint8], entries: Sequence[tuple[str, tuple[int, int, int]]]
                ) -> NDArray[np.uint8]:
    """``image`` with a legend strip below it: one coloured line and text per entry, laid out
    left to right and wrapped to the image's width."""
    pad, line = 6, text_size("Ag")[1] + 4
    width = image.shape[1]
    rows: list[list[tuple[str, tuple[int, int, int]]]] = [[]]
    used = pad
    for text, colour in entries:
        need = 22 + text_size(text)[0] + 2 * pad
        if rows[-1] and used + need > width:
            rows.append([])
            used = pad
        rows[-1].append((text, colour))
        used += need
    strip = np.zeros((line * len(rows) + pad, width, 3), np.uint8)
    for r, row in enumerate(rows):
        x, y = pad, pad + line * r + line // 2
        for text, colour in row:
            for col, th in ((HALO_COLOUR, 4), (colour, 2)):
                cv2.line(strip, (x, y), (x + 16, y), col, th, cv2.LINE_AA)
            draw_text(strip, text, (x + 22, y + line // 2 - 5), (235, 235, 235))
            x += 22 + text_size(text)[0] + 2 * pad
    return np.ascontiguousarray(np.vstack([image, strip]))


def marker_box(uv: tuple[float, float], size: int = 10) -> tuple[int, int, int, int]:
    """The box a marker of ``size`` px at ``uv`` covers (labels keep off it)."""
    half = size // 2 + 2
    return round(uv[0]) - half, round(uv[1]) - half, round(uv[0]) + half, round(uv[1]) + half


def upscale(image: NDArray[np.uint8], factor: int) -> NDArray[np.uint8]:
    """Nearest-neighbour enlargement so thin overlays stay readable on small frames."""
    return np.repeat(np.repeat(image, factor, axis=0), factor, axis=1)


def bgr_canvas(image: NDArray[np.uint8], factor: int = OVERLAY_SCALE) -> NDArray[np.uint8]:
    """A BGR copy of an RGB, RGBA or grey uint8 image, enlarged ``factor`` times."""
    if image.ndim == 2:
        rgb = np.repeat(image[..., None], 3, axis=2)
    else:
        rgb = image[..., :3]
    return np.ascontiguousarray(upscale(np.ascontiguousarray(rgb[..., ::-1]), factor))


def draw_pose(image: NDArray[np.uint8], centre_px: tuple[float, float],
              centre_cam: NDArray[np.float64], normal_cam: NDArray[np.float64],
              radius_m: float, intrinsics: CameraIntrinsics, k: float
              ) -> list[tuple[int, int, int, int]]:
    """The pose of a face: a cross at its centre and an arrow along its outward normal
    (towards the camera side of the face), ``NORMAL_LENGTH`` radii long, projected; returns
    the boxes they cover."""
    outward = -np.asarray(normal_cam, dtype=float)
    tip_cam = np.asarray(centre_cam, dtype=float) + NORMAL_LENGTH * radius_m * outward
    start = scale_point(centre_px, k)
    covered = [marker_box(start, 16)]
    if tip_cam[2] > 1e-6:
        tip = scale_point(intrinsics.project(tip_cam)[0], k)
        draw_arrow(image, start, tip, NORMAL_COLOUR)
        covered.append(marker_box(tip, 16))
    draw_marker(image, start, TOP_COLOUR, 16, 2)
    return covered


def truth_overlay(image_rgb: NDArray[np.uint8], truth: FrameTruth,
                  k: int = OVERLAY_SCALE) -> NDArray[np.uint8]:
    """BGR picture, ``k`` times enlarged: each object's ground-truth face ellipse (green: top
    objects, orange: the others) with a cross at its projected face centre and a label with
    its name, visible share and TOP; faces hidden entirely (0 % visible) are not drawn."""
    out = bgr_canvas(image_rgb, k)
    labels, centres = [], []
    for obj in truth.objects:
        if obj.ellipse is None or round(100 * obj.visible_fraction) == 0:
            continue
        colour = TOP_COLOUR if obj.is_top else OTHER_COLOUR
        scaled = scale_ellipse(obj.ellipse, k)
        draw_ellipse(out, scaled, colour, thickness=1)
        centre = scale_point(obj.face_center_px, k)
        draw_marker(out, centre, colour)
        centres.append(marker_box(centre))
        text = f"{obj.name} {100 * obj.visible_fraction:.0f}%" + (" TOP" if obj.is_top else "")
        labels.append(Label(text, colour, scaled))
    draw_labels(out, labels, centres)
    return with_legend(out, [("top object: nothing on it, face >= 98 % visible", TOP_COLOUR),
                             ("other object: share of its face visible", OTHER_COLOUR),
                             ("+ projected face centre", (235, 235, 235))])


def detection_overlay(image: NDArray[np.uint8], detection: Detection,
                      intrinsics: CameraIntrinsics | None,
                      k: int = OVERLAY_SCALE) -> NDArray[np.uint8]:
    """BGR picture, ``k`` times enlarged, of a detector's result: every ellipse labelled with
    its index and support (green and TOP: the top object), the top face's pose (a cross at its
    centre, an arrow along its normal, when ``intrinsics`` are known) and a legend."""
    out = bgr_canvas(image, k)
    entries = [("top object: [index] support TOP", TOP_COLOUR),
               ("other ellipse: [index] support", OTHER_COLOUR)]
    if detection.pose is not None and intrinsics is not None:
        entries.append(("top face's normal, + its centre", NORMAL_COLOUR))
    labels = []
    for i, det in enumerate(detection.ellipses):
        top = i == detection.top
        colour = TOP_COLOUR if top else OTHER_COLOUR
        scaled = scale_ellipse(det.ellipse, k)
        draw_ellipse(out, scaled, colour, thickness=2 if top else 1)
        labels.append(Label(f"[{i}] {det.support:.2f}" + (" TOP" if top else ""), colour,
                            scaled))
    pose = detection.pose
    blocked: list[tuple[int, int, int, int]] = []
    if pose is not None and intrinsics is not None:
        blocked = draw_pose(out, (pose.x, pose.y), pose.centre_cam, pose.normal_cam,
                            pose.radius_m, intrinsics, k)
    draw_labels(out, labels, blocked)
    if not detection:
        entries.append((f"no top object: {detection.reason}", (90, 90, 255)))
    return with_legend(out, entries)
