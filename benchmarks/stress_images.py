"""Procedural stress images for the detector: inputs unlike its rendered piles.

Every image is a pure function of (kind, seed, width, height), so a stress run is
reproducible without stored files. Kinds:

- ``noise``: uniform and Gaussian pixel noise (edges everywhere, none of them long);
- ``texture``: sums of random gratings and a checkerboard (long straight and wavy edges);
- ``small_ellipses``: hundreds of small filled and outlined ellipses (many short closed
  chains, many candidate faces);
- ``target``: concentric rings and a road-sign disc with a border and glyphs (nested
  ellipses sharing a centre, the top rule's last-resort steps' worst case);
- ``clutter``: photo-like clutter: a sky-to-ground gradient, blurred blobs, polygons, lines,
  text and a few discs, with noise.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

KINDS = ("noise", "texture", "small_ellipses", "target", "clutter")


def _noise(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    if rng.random() < 0.5:
        return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    img = rng.normal(128, rng.uniform(5, 60), (h, w, 3))
    return np.clip(img, 0, 255).astype(np.uint8)


def _texture(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.zeros((h, w, 3))
    for _ in range(int(rng.integers(2, 6))):
        f = rng.uniform(0.02, 0.4)
        t = rng.uniform(0, np.pi)
        wave = np.sin(f * (np.cos(t) * xx + np.sin(t) * yy) + rng.uniform(0, 6.3))
        img += wave[..., None] * rng.uniform(10, 60, 3)
    if rng.random() < 0.5:
        side = int(rng.integers(4, 24))
        img += 60.0 * (((xx // side) + (yy // side)) % 2)[..., None]
    return np.clip(img + 128, 0, 255).astype(np.uint8)


def _small_ellipses(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    img = np.full((h, w, 3), rng.integers(0, 256, 3), np.uint8)
    count = int(rng.integers(100, 600)) * max(1, (h * w) // (320 * 240))
    for _ in range(count):
        a = float(rng.uniform(2, 14))
        axes = (max(1, round(a)), max(1, round(a * rng.uniform(0.3, 1.0))))
        centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        cv2.ellipse(img, centre, axes, float(rng.uniform(0, 180)), 0, 360, colour,
                    -1 if rng.random() < 0.6 else 1, cv2.LINE_AA)
    return img


def _target(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    img = np.full((h, w, 3), rng.integers(100, 220, 3), np.uint8)
    centre = (int(w * rng.uniform(0.3, 0.7)), int(h * rng.uniform(0.3, 0.7)))
    rmax = int(min(h, w) * rng.uniform(0.3, 0.48))
    squash = rng.uniform(0.5, 1.0)
    angle = float(rng.uniform(0, 180))
    rings = int(rng.integers(3, 12))
    for k in range(rings, 0, -1):
        r = max(2, rmax * k // rings)
        colour = (230, 230, 230) if k % 2 else tuple(int(c) for c in rng.integers(0, 120, 3))
        cv2.ellipse(img, centre, (r, max(1, int(r * squash))), angle, 0, 360, colour, -1,
                    cv2.LINE_AA)
    for _ in range(int(rng.integers(0, 4))):
        org = (int(rng.integers(0, w // 2)), int(rng.integers(h // 4, h)))
        cv2.putText(img, "STOP 50", org, cv2.FONT_HERSHEY_SIMPLEX, rng.uniform(0.5, 2.0),
                    (0, 0, 0), int(rng.integers(1, 4)), cv2.LINE_AA)
    return _blur_noise(rng, img)


def _clutter(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    top, bottom = rng.integers(0, 256, 3), rng.integers(0, 256, 3)
    ramp = np.linspace(0.0, 1.0, h)[:, None, None]
    img = np.ascontiguousarray(np.broadcast_to(top + (bottom - top) * ramp, (h, w, 3))
                               .astype(np.uint8))
    scale = max(w, h) / 320.0
    for _ in range(int(rng.integers(20, 80))):
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        shape = rng.integers(0, 5)
        p = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        if shape == 0:
            pts = rng.integers(0, [w, h], (int(rng.integers(3, 7)), 2)).astype(np.int32)
            cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
        elif shape == 1:
            q = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            cv2.line(img, p, q, colour, int(rng.integers(1, 6)), cv2.LINE_AA)
        elif shape == 2:
            r = int(rng.uniform(3, 60) * scale)
            cv2.ellipse(img, p, (r, max(1, int(r * rng.uniform(0.3, 1)))),
                        float(rng.uniform(0, 180)), 0, 360, colour, -1, cv2.LINE_AA)
        elif shape == 3:
            cv2.putText(img, "Ag8@%", p, cv2.FONT_HERSHEY_DUPLEX, rng.uniform(0.4, 2.5) * scale,
                        colour, int(rng.integers(1, 4)), cv2.LINE_AA)
        else:
            q = (p[0] + int(rng.integers(5, 80) * scale), p[1] + int(rng.integers(5, 80) * scale))
            cv2.rectangle(img, p, q, colour, -1)
    k = 2 * int(rng.integers(0, 3)) + 1
    img = cv2.GaussianBlur(img, (k, k), 0) if k > 1 else img
    return _blur_noise(rng, img)


def _blur_noise(rng: np.random.Generator, img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    noisy = img.astype(np.float64) + rng.normal(0, rng.uniform(0, 6), img.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8)


_MAKERS = {"noise": _noise, "texture": _texture, "small_ellipses": _small_ellipses,
           "target": _target, "clutter": _clutter}


def stress_image(kind: str, seed: int, width: int = 320, height: int = 240
                 ) -> NDArray[np.uint8]:
    """The (height, width, 3) uint8 RGB stress image of ``kind`` (see KINDS) for ``seed``."""
    rng = np.random.default_rng([KINDS.index(kind), seed])
    return _MAKERS[kind](rng, height, width)
