"""Seeded synthetic images of cylinder stacks seen from above, with exact ground truth.

A stand-in for the simulator's renders while it is being built, and a source of unit-test
images afterwards. Each cylinder is drawn in painter's order (later = higher in the pile):
its side wall as the convex hull of the two projected rims, then its top face as the exact
perspective image of the rim circle (:func:`stackpick_sim.geometry.project_circle`). The
image is rendered ``SUPERSAMPLE`` times larger and area-averaged down, so edges carry
sub-pixel information as a real camera's would; then light gain and Gaussian pixel noise are
applied.

Ground truth per object: the face ellipse, face-centre pixel, tilt angles, visible fraction of
the face and whether it is a *top object* (no later-drawn object overlaps any part of it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import SceneGenerationError
from stackpick_sim.geometry import (
    CameraIntrinsics,
    Ellipse,
    FloatArray,
    plane_basis,
    project_circle,
    tilt_angles,
)

#: Render scale before area-averaging down; 4x gives edges accurate to ~1/16 px.
SUPERSAMPLE = 4
#: Points per projected rim polygon; chord error on a 45 px rim is < 0.01 px.
RIM_POINTS = 180
#: Scene generation attempts before giving up (a placement is rejected if it leaves the image).
MAX_ATTEMPTS = 200
#: Wall brightness relative to the face: the ring light hits the face square on, the wall
#: obliquely. Placeholder, not identified from the simulator.
WALL_SHADE = 0.45
#: Belt grey level (0-255) before light gain: "dark grey belt".
BELT_GREY = 55.0


@dataclass(frozen=True, kw_only=True)
class CylinderKind:
    """A cylinder model: radius and height in metres."""

    radius_m: float
    height_m: float


#: Two kinds of taller cylinders for synthetic tests (the radii of the paper scene's kinds; the
#: simulator's cylinders are squatter: scenes/paper.toml). Taller walls test the wall cues harder.
PAPER_KINDS: tuple[CylinderKind, ...] = (
    CylinderKind(radius_m=0.035, height_m=0.055),
    CylinderKind(radius_m=0.025, height_m=0.04),
)

#: Distinct matte face colours (RGB 0-255), some of near-equal luminance on purpose.
PALETTE: tuple[tuple[int, int, int], ...] = (
    (220, 60, 50), (60, 170, 70), (60, 100, 220), (230, 200, 60), (200, 90, 200),
    (70, 200, 200), (235, 140, 50), (160, 160, 160),
)


@dataclass(frozen=True, kw_only=True)
class SyntheticConfig:
    """Scene parameters; distances in metres, angles in degrees, grey levels 0-255."""

    width: int = 320
    height: int = 240
    fovy_deg: float = 45.0
    camera_height_m: float = 0.30
    n_objects: tuple[int, int] = (3, 5)
    max_tilt_deg: float = 45.0
    #: Standard deviation of horizontal object offsets from the pile centre.
    pile_spread_m: float = 0.03
    #: Height gained per object already in the pile (a crude stand-in for physics).
    stack_step_m: float = 0.008
    noise_sigma: tuple[float, float] = (0.0, 3.0)
    light_gain: tuple[float, float] = (0.85, 1.15)
    kinds: tuple[CylinderKind, ...] = PAPER_KINDS

    def __post_init__(self) -> None:
        lo, hi = self.n_objects
        if not 1 <= lo <= hi:
            raise ValueError(f"n_objects must be 1 <= lo <= hi, got {self.n_objects}")
        if not 0.0 <= self.max_tilt_deg < 80.0:
            raise ValueError(f"max_tilt_deg must be in [0, 80), got {self.max_tilt_deg}")

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera's pinhole intrinsics."""
        return CameraIntrinsics.from_fovy(self.fovy_deg, self.width, self.height)


@dataclass(frozen=True, kw_only=True)
class SyntheticObject:
    """Ground truth of one rendered cylinder (camera frame, metres; pixels; degrees)."""

    ellipse: Ellipse
    centre_cam: FloatArray
    normal_cam: FloatArray
    radius_m: float
    height_m: float
    face_center_px: tuple[float, float]
    theta_x_deg: float
    theta_y_deg: float
    visible_fraction: float
    is_top: bool


@dataclass(frozen=True, kw_only=True)
class SyntheticScene:
    """A rendered (H, W, 3) uint8 RGB image and its objects in drawing (bottom-up) order."""

    image: NDArray[np.uint8]
    intrinsics: CameraIntrinsics
    objects: tuple[SyntheticObject, ...]
    top_indices: tuple[int, ...] = field(default=())


def _rim(centre: FloatArray, normal: FloatArray, radius: float, n: int) -> FloatArray:
    """(n, 3) camera-frame points on a circle of ``radius`` m about ``normal``."""
    u, v = plane_basis(normal)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return centre + radius * (np.outer(np.cos(t), u) + np.outer(np.sin(t), v))


def _to_fixed(pixels: FloatArray, scale: int, shift: int) -> NDArray[np.int32]:
    """Pixel-centre coordinates to fixed-point coordinates of a ``scale``x canvas."""
    big = (pixels + 0.5) * scale - 0.5
    return np.round(big * (1 << shift)).astype(np.int32)


def cylinder_outlines(centre: FloatArray, normal: FloatArray, radius: float, height: float,
                      intrinsics: CameraIntrinsics) -> tuple[FloatArray, FloatArray]:
    """Projected face rim (RIM_POINTS, 2) and wall hull (M, 2) of a cylinder, pixels.

    ``centre`` is the visible face's centre and ``normal`` its inward normal (into the
    object), both camera frame; the bottom rim lies ``height`` m along ``normal``.
    """
    top = intrinsics.project(_rim(centre, normal, radius, RIM_POINTS))
    bottom = intrinsics.project(_rim(centre + height * normal, normal, radius, RIM_POINTS))
    hull = cv2.convexHull(np.vstack([top, bottom]).astype(np.float32))[:, 0, :]
    return top, hull.astype(float)


def render_cylinders(objects: list[tuple[FloatArray, FloatArray, float, float]],
                     colours: list[tuple[int, int, int]], intrinsics: CameraIntrinsics,
                     *, belt_grey: float = BELT_GREY) -> NDArray[np.float32]:
    """Noise-free (H, W, 3) float32 RGB render of cylinders in painter's order.

    ``objects`` holds (face centre (3,), inward normal (3,), radius m, height m) per cylinder,
    camera frame, drawn first to last; ``colours`` the face RGB of each.
    """
    s, shift = SUPERSAMPLE, 4
    canvas = np.full((intrinsics.height * s, intrinsics.width * s, 3), belt_grey, np.float32)
    for (centre, normal, radius, height), colour in zip(objects, colours, strict=True):
        face, hull = cylinder_outlines(centre, normal, radius, height, intrinsics)
        wall = tuple(float(c) * WALL_SHADE for c in colour)
        cv2.fillConvexPoly(canvas, _to_fixed(hull, s, shift), wall, cv2.LINE_8, shift)
        cv2.fillPoly(canvas, [_to_fixed(face, s, shift)], tuple(float(c) for c in colour),
                     cv2.LINE_8, shift)
    small = cv2.resize(canvas, (intrinsics.width, intrinsics.height), interpolation=cv2.INTER_AREA)
    return np.asarray(small, np.float32)


def _silhouette_mask(hull: FloatArray, face: FloatArray, shape: tuple[int, int]
                     ) -> NDArray[np.bool_]:
    """(H, W) mask of a cylinder's whole projection at 1x (pixel centres inside)."""
    m = np.zeros(shape, np.uint8)
    cv2.fillConvexPoly(m, _to_fixed(hull, 1, 4), 1, cv2.LINE_8, 4)
    cv2.fillPoly(m, [_to_fixed(face, 1, 4)], 1, cv2.LINE_8, 4)
    return m.astype(bool)


def _random_normal(rng: np.random.Generator, max_tilt_deg: float) -> FloatArray:
    """Inward face normal tilted uniformly up to ``max_tilt_deg`` from the optical axis."""
    tilt = math.radians(rng.uniform(0.0, max_tilt_deg))
    phi = rng.uniform(0.0, 2.0 * math.pi)
    return np.array([math.sin(tilt) * math.cos(phi), math.sin(tilt) * math.sin(phi),
                     math.cos(tilt)])


def generate_stack(rng: np.random.Generator, config: SyntheticConfig | None = None
                   ) -> SyntheticScene:
    """Render one seeded stack; raises SceneGenerationError if no placement fits the image."""
    cfg = config or SyntheticConfig()
    k = cfg.intrinsics
    shape = (k.height, k.width)
    n = int(rng.integers(cfg.n_objects[0], cfg.n_objects[1] + 1))
    for _ in range(MAX_ATTEMPTS):
        pile = rng.normal(0.0, 0.015, size=2)
        placed: list[tuple[FloatArray, FloatArray, float, float]] = []
        outlines: list[tuple[FloatArray, FloatArray]] = []
        inside = True
        for i in range(n):
            kind = cfg.kinds[int(rng.integers(len(cfg.kinds)))]
            height = kind.height_m * rng.uniform(0.95, 1.1)
            normal = _random_normal(rng, cfg.max_tilt_deg)
            xy = pile + rng.normal(0.0, cfg.pile_spread_m, size=2)
            # The face sits one object height (along the axis) above the pile's level.
            z = cfg.camera_height_m - i * cfg.stack_step_m - height * normal[2]
            centre = np.array([xy[0], xy[1], z])
            face, hull = cylinder_outlines(centre, normal, kind.radius_m, height, k)
            if (hull.min() < 2.0 or hull[:, 0].max() > k.width - 3
                    or hull[:, 1].max() > k.height - 3):
                inside = False
                break
            placed.append((centre, normal, kind.radius_m, height))
            outlines.append((face, hull))
        if inside:
            break
    else:
        raise SceneGenerationError(f"no {n}-object stack fit a {k.width}x{k.height} image in "
                                   f"{MAX_ATTEMPTS} attempts")
    colour_ids = rng.permutation(len(PALETTE))[:n]
    colours = [PALETTE[int(c)] for c in colour_ids]
    image = render_cylinders(placed, colours, k)
    gain = rng.uniform(*cfg.light_gain)
    sigma = rng.uniform(*cfg.noise_sigma)
    noisy = image * gain + rng.normal(0.0, 1.0, image.shape).astype(np.float32) * sigma
    rgb = np.clip(np.round(noisy), 0, 255).astype(np.uint8)

    silhouettes = [_silhouette_mask(hull, face, shape) for face, hull in outlines]
    above = np.zeros(shape, bool)
    objects: list[SyntheticObject] = []
    for i in range(n - 1, -1, -1):
        centre, normal, radius, height = placed[i]
        ellipse = project_circle(centre, normal, radius, k)
        face_mask = ellipse.mask(shape)
        area = max(1, int(np.count_nonzero(face_mask)))
        visible = 1.0 - np.count_nonzero(face_mask & above) / area
        is_top = not np.any(silhouettes[i] & above)
        above |= silhouettes[i]
        tx, ty = tilt_angles(normal)
        centre_px = k.project(centre)[0]
        objects.append(SyntheticObject(
            ellipse=ellipse, centre_cam=centre, normal_cam=normal, radius_m=radius,
            height_m=height, face_center_px=(float(centre_px[0]), float(centre_px[1])),
            theta_x_deg=tx, theta_y_deg=ty, visible_fraction=float(visible), is_top=is_top))
    objects.reverse()
    tops = tuple(i for i, o in enumerate(objects) if o.is_top)
    return SyntheticScene(image=rgb, intrinsics=k, objects=tuple(objects), top_indices=tops)


def draw_ellipses(shape: tuple[int, int], ellipses: list[Ellipse], *, fill: bool = True,
                  background: float = 40.0, foreground: float = 200.0,
                  noise_sigma: float = 0.0, rng: np.random.Generator | None = None
                  ) -> NDArray[np.uint8]:
    """(H, W) uint8 image of ellipses drawn in order (anti-aliased by supersampling).

    Filled discs when ``fill``, else 1.5 px outlines; Gaussian noise of ``noise_sigma`` grey
    levels from ``rng``. For unit tests of the detector's fitting stages.
    """
    s, shift = SUPERSAMPLE, 4
    h, w = shape
    canvas = np.full((h * s, w * s), background, np.float32)
    for i, e in enumerate(ellipses):
        pts = _to_fixed(e.points(RIM_POINTS), s, shift)
        grey = foreground if i % 2 == 0 else 0.5 * (foreground + background) + 25.0
        if fill:
            cv2.fillPoly(canvas, [pts], grey, cv2.LINE_8, shift)
        else:
            cv2.polylines(canvas, [pts], True, foreground, int(1.5 * s), cv2.LINE_8, shift)
    out = np.asarray(cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA), np.float32)
    if noise_sigma > 0.0:
        gen = rng if rng is not None else np.random.default_rng(0)
        out = out + gen.normal(0.0, noise_sigma, out.shape).astype(np.float32)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)
