"""Procedural images of known ellipses on textured backgrounds, for ellipse precision.

Every image is a pure function of (family, seed): one to three filled discs (ellipses of
varied size, tilt and contrast, some partly hidden by a patch of background drawn over them)
on a background of one family:

- ``glyphs``: lines of text in several Hershey fonts, sizes and stroke widths (round letters,
  digits and symbols: O, o, 0, Q, @, %, 8);
- ``logos``: stroked rings, C-shaped arcs, crescents and badges (circle outlines with text);
- ``reliefs``: embossed shading of glyphs and blobs (a bright and a dark edge side by side);
- ``foliage``: many overlapping irregular blobs in related colours;
- ``labels``: printed labels: text, bar codes, small printed circles and dots.

The truth is the list of disc ellipses; background shapes are never truth (a printed ring,
a letter O or a crescent is texture for a detector of round objects).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.geometry import Ellipse

FAMILIES = ("glyphs", "logos", "reliefs", "foliage", "labels")
FONTS = (cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_COMPLEX,
         cv2.FONT_HERSHEY_TRIPLEX, cv2.FONT_HERSHEY_PLAIN, cv2.FONT_HERSHEY_SCRIPT_SIMPLEX)
TEXT = "OoQ0@%8 BbdpqgeaDC6G9 STOP 50 Lot 0809 Bio COOL e@o.com 100% Qa"

Colour = tuple[int, int, int]


def _colour(rng: np.random.Generator) -> Colour:
    return (int(rng.integers(0, 256)), int(rng.integers(0, 256)), int(rng.integers(0, 256)))


def _text(rng: np.random.Generator, img: NDArray[np.uint8], count: int, colour: Colour | None
          = None, scale: tuple[float, float] = (0.4, 3.0)) -> None:
    h, w = img.shape[:2]
    for _ in range(count):
        start = int(rng.integers(0, len(TEXT) - 8))
        words = TEXT[start:start + int(rng.integers(3, 12))]
        org = (int(rng.integers(-20, w - 10)), int(rng.integers(10, h + 10)))
        cv2.putText(img, words, org, FONTS[int(rng.integers(0, len(FONTS)))],
                    float(rng.uniform(*scale)), colour or _colour(rng),
                    int(rng.integers(1, 6)), cv2.LINE_AA)


def _glyphs(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    img = np.full((h, w, 3), _colour(rng), np.uint8)
    _text(rng, img, int(rng.integers(8, 25)))
    return img


def _logos(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    img = np.full((h, w, 3), _colour(rng), np.uint8)
    for _ in range(int(rng.integers(4, 10))):
        c = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        r = int(rng.integers(8, 60))
        axes = (r, max(4, int(r * rng.uniform(0.5, 1.0))))
        ang = float(rng.uniform(0, 180))
        kind = int(rng.integers(0, 4))
        if kind == 0:  # stroked ring
            cv2.ellipse(img, c, axes, ang, 0, 360, _colour(rng), int(rng.integers(1, 7)),
                        cv2.LINE_AA)
        elif kind == 1:  # C-shaped arc
            a0 = float(rng.uniform(0, 360))
            cv2.ellipse(img, c, axes, ang, a0, a0 + float(rng.uniform(120, 300)),
                        _colour(rng), int(rng.integers(2, 9)), cv2.LINE_AA)
        elif kind == 2:  # crescent
            bg = tuple(int(v) for v in img[min(h - 1, max(0, c[1])), min(w - 1, max(0, c[0]))])
            cv2.ellipse(img, c, axes, ang, 0, 360, _colour(rng), -1, cv2.LINE_AA)
            off = (c[0] + int(r * rng.uniform(0.3, 0.6)), c[1] + int(r * rng.uniform(-0.3, 0.3)))
            cv2.ellipse(img, off, axes, ang, 0, 360, bg, -1, cv2.LINE_AA)
        else:  # badge: a ring with text across it
            cv2.ellipse(img, c, axes, ang, 0, 360, _colour(rng), int(rng.integers(2, 6)),
                        cv2.LINE_AA)
            cv2.putText(img, "Co", (c[0] - r // 2, c[1] + r // 4), FONTS[1], r / 25.0,
                        _colour(rng), max(1, r // 12), cv2.LINE_AA)
    _text(rng, img, int(rng.integers(1, 4)))
    return img


def _blobs(rng: np.random.Generator, h: int, w: int, scale: float) -> NDArray[np.float64]:
    """(h, w) smooth random field, features about ``scale`` px wide."""
    small = rng.normal(0, 1, (max(2, int(h / scale)), max(2, int(w / scale))))
    return np.asarray(cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC))


def _reliefs(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    sheet = np.zeros((h, w, 3), np.uint8)
    _text(rng, sheet, int(rng.integers(4, 12)), (255, 255, 255), (0.8, 3.5))
    mask = np.maximum(sheet[..., 0], ((_blobs(rng, h, w, 30) > 1.0) * 255).astype(np.uint8))
    height = cv2.GaussianBlur(mask.astype(np.float64) / 255.0, (0, 0), float(rng.uniform(0.8, 2)))
    t = float(rng.uniform(0, 2 * np.pi))
    shade = np.cos(t) * cv2.Sobel(height, cv2.CV_64F, 1, 0) + np.sin(t) * cv2.Sobel(
        height, cv2.CV_64F, 0, 1)
    base = np.asarray(_colour(rng), np.float64)
    img = base + float(rng.uniform(40, 120)) * shade[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)


def _foliage(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    img = np.zeros((h, w, 3))
    green = np.array([40.0, 120.0, 40.0]) + rng.uniform(-30, 30, 3)
    img[:] = green * 0.5
    for scale in (40.0, 20.0, 10.0):
        for _ in range(2):
            leaf = _blobs(rng, h, w, scale) > float(rng.uniform(0.3, 1.0))
            img[leaf] = np.clip(green * rng.uniform(0.6, 1.6) + rng.uniform(-20, 20, 3), 0, 255)
    return img.astype(np.uint8)


def _labels(rng: np.random.Generator, h: int, w: int) -> NDArray[np.uint8]:
    img = np.full((h, w, 3), _colour(rng), np.uint8)
    for _ in range(int(rng.integers(2, 5))):
        x0, y0 = int(rng.integers(0, w - 40)), int(rng.integers(0, h - 30))
        x1, y1 = x0 + int(rng.integers(60, 200)), y0 + int(rng.integers(40, 120))
        paper = (int(rng.integers(200, 256)),) * 3
        cv2.rectangle(img, (x0, y0), (x1, y1), paper, -1)
        ink = (int(rng.integers(0, 80)),) * 3
        for k in range(int(rng.integers(6, 20))):  # bar code
            x = x0 + 5 + 3 * k
            cv2.line(img, (x, y1 - 20), (x, y1 - 5), ink, int(rng.integers(1, 3)))
        for _ in range(int(rng.integers(3, 10))):  # small printed circles and dots
            c = (int(rng.integers(x0, x1)), int(rng.integers(y0, y1)))
            if rng.random() < 0.5:
                cv2.circle(img, c, int(rng.integers(4, 14)), ink, int(rng.integers(1, 3)),
                           cv2.LINE_AA)
            else:
                cv2.circle(img, c, int(rng.integers(1, 5)), ink, -1, cv2.LINE_AA)
        sub = img[y0:y1, x0:x1]
        _text(rng, sub, int(rng.integers(2, 6)), ink, (0.3, 1.0))
    return img


_MAKERS = {"glyphs": _glyphs, "logos": _logos, "reliefs": _reliefs, "foliage": _foliage,
           "labels": _labels}


def _discs(rng: np.random.Generator, img: NDArray[np.uint8]) -> list[Ellipse]:
    """Draw one to three discs on ``img``; their ellipses, some partly hidden."""
    h, w = img.shape[:2]
    truth: list[Ellipse] = []
    for _ in range(int(rng.integers(1, 4))):
        a = float(rng.uniform(8, 55))
        e = Ellipse(cx=float(rng.uniform(a, w - a)), cy=float(rng.uniform(a, h - a)), a=a,
                    b=a * float(rng.uniform(0.45, 1.0)), angle_deg=float(rng.uniform(0, 180)))
        under = img[int(e.cy), int(e.cx)].astype(np.int64)
        step = rng.uniform(25, 120) * rng.choice([-1, 1], 3)
        colour = tuple(int(v) for v in np.clip(under + step, 0, 255))
        cv2.ellipse(img, ((e.cx, e.cy), (2 * e.a, 2 * e.b), e.angle_deg), colour, -1,
                    cv2.LINE_AA)
        truth.append(e)
    if rng.random() < 0.5:  # a patch of background over part of one disc
        e = truth[int(rng.integers(0, len(truth)))]
        x0, y0 = int(e.cx + rng.uniform(-0.2, 0.6) * e.a), int(e.cy - 1.5 * e.a)
        rows = slice(max(0, y0), min(h, y0 + int(3 * e.a)))
        img[rows, max(0, x0):min(w, x0 + int(1.5 * e.a))] = img[0, 0]
    return truth


def precision_image(family: str, seed: int, width: int = 320, height: int = 240
                    ) -> tuple[NDArray[np.uint8], list[Ellipse]]:
    """The (height, width, 3) uint8 RGB image of ``family`` (see FAMILIES) for ``seed`` and
    its true ellipses (the discs')."""
    rng = np.random.default_rng([FAMILIES.index(family), seed])
    img = np.ascontiguousarray(_MAKERS[family](rng, height, width))
    truth = _discs(rng, img)
    img = cv2.GaussianBlur(img, (3, 3), 0) if rng.random() < 0.5 else img
    noisy = img.astype(np.float64) + rng.normal(0, rng.uniform(0, 5), img.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8), truth
