"""Precision and recall of find_ellipses on textured images with known ellipses.

    python benchmarks/bench_ellipses_precision.py [--seeds 0:40] [--min-axis 5,10,20]
        [--overlays DIR]

Runs :func:`stackpick_sim.vision.find_ellipses` (default support bound) on the images of
:mod:`precision_images` (discs on glyphs, logos, reliefs, foliage and labels) for each
``min_axis_px``. A reported ellipse is a true positive when its area overlaps a true disc's
by an intersection over union >= 0.8 (each disc matched once); discs whose semi-minor axis
is below ``min_axis_px`` are neither counted as missed nor as found (a detection matching
one is ignored). Prints precision and recall per background family and overall;
``--overlays`` writes each image with the truth (green) and the detections (red: false,
blue: true) as PNGs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

from precision_images import FAMILIES, precision_image

from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision import find_ellipses

MIN_IOU = 0.8


def _mask(e: Ellipse, shape: tuple[int, int], pad: int) -> NDArray[np.bool_]:
    m = np.zeros((shape[0] + 2 * pad, shape[1] + 2 * pad), np.uint8)
    cv2.ellipse(m, ((e.cx + pad, e.cy + pad), (2 * e.a, 2 * e.b), e.angle_deg), 1, -1)
    return m.astype(bool)


def iou(e: Ellipse, f: Ellipse, shape: tuple[int, int]) -> float:
    """Area intersection over union of two ellipses (rasterised, image plus a margin)."""
    pad = int(max(e.a, f.a)) + 2
    m, n = _mask(e, shape, pad), _mask(f, shape, pad)
    union = int((m | n).sum())
    return float((m & n).sum()) / union if union else 0.0


def score(found: list[Ellipse], truth: list[Ellipse], min_axis: float,
          shape: tuple[int, int]) -> tuple[int, int, int, int, list[bool]]:
    """(true positives, false positives, discs counted, discs found, per detection: true)."""
    used: set[int] = set()
    tp = fp = 0
    flags = []
    for f in found:
        best = max(range(len(truth)), key=lambda k: iou(f, truth[k], shape), default=None)
        hit = best is not None and best not in used and iou(f, truth[best], shape) >= MIN_IOU
        if hit and truth[best].b >= min_axis:
            used.add(best)
            tp += 1
        elif not hit:
            fp += 1
        flags.append(hit)
    counted = sum(1 for t in truth if t.b >= min_axis)
    return tp, fp, counted, len(used), flags


def _overlay(img: NDArray[np.uint8], truth: list[Ellipse], found: list[Ellipse],
             flags: list[bool], path: Path) -> None:
    out = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    for e in truth:
        cv2.ellipse(out, ((e.cx, e.cy), (2 * e.a, 2 * e.b), e.angle_deg), (0, 255, 0), 1)
    for e, ok in zip(found, flags, strict=True):
        cv2.ellipse(out, ((e.cx, e.cy), (2 * e.a, 2 * e.b), e.angle_deg),
                    (255, 0, 0) if ok else (0, 0, 255), 1)
    cv2.imwrite(str(path), cv2.resize(out, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST))


def run(seeds: range, min_axes: list[float], overlays: Path | None
        ) -> dict[tuple[str, float], tuple[int, int, int, int]]:
    """(family, min_axis) -> summed (tp, fp, discs counted, discs found)."""
    totals: dict[tuple[str, float], tuple[int, int, int, int]] = {}
    for family in FAMILIES:
        for seed in seeds:
            img, truth = precision_image(family, seed)
            for min_axis in min_axes:
                found = [s.ellipse for s in find_ellipses(img, min_axis_px=min_axis)]
                tp, fp, n, k, flags = score(found, truth, min_axis, img.shape[:2])
                old = totals.get((family, min_axis), (0, 0, 0, 0))
                totals[(family, min_axis)] = (old[0] + tp, old[1] + fp, old[2] + n, old[3] + k)
                if overlays is not None and min_axis == min_axes[0]:
                    _overlay(img, truth, found, flags, overlays / f"{family}_{seed}.png")
    return totals


def _ratio(num: int, den: int) -> str:
    return f"{100.0 * num / den:5.1f} %" if den else "    -  "


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", default="0:40", help="seed range start:stop")
    parser.add_argument("--min-axis", default="5,10,20", help="min_axis_px values, px")
    parser.add_argument("--overlays", type=Path, default=None, help="directory for PNGs")
    args = parser.parse_args()
    lo, hi = (int(v) for v in args.seeds.split(":"))
    min_axes = [float(v) for v in args.min_axis.split(",")]
    if args.overlays is not None:
        args.overlays.mkdir(parents=True, exist_ok=True)
    totals = run(range(lo, hi), min_axes, args.overlays)
    print(f"{'family':10s} {'min_axis':>8s} {'TP':>5s} {'FP':>5s} {'precision':>9s} "
          f"{'recall':>8s} ({len(range(lo, hi))} images a family)")
    for min_axis in min_axes:
        all_tp = all_fp = all_n = all_k = 0
        for family in FAMILIES:
            tp, fp, n, k = totals[(family, min_axis)]
            all_tp, all_fp, all_n, all_k = all_tp + tp, all_fp + fp, all_n + n, all_k + k
            print(f"{family:10s} {min_axis:8.0f} {tp:5d} {fp:5d} {_ratio(tp, tp + fp):>9s} "
                  f"{_ratio(k, n):>8s}")
        print(f"{'all':10s} {min_axis:8.0f} {all_tp:5d} {all_fp:5d} "
              f"{_ratio(all_tp, all_tp + all_fp):>9s} {_ratio(all_k, all_n):>8s}")


if __name__ == "__main__":
    main()
