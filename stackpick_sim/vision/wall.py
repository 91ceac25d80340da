"""Side-wall evidence: does the image show a cylinder's wall where a pose solution predicts it?

A circular face seen as an ellipse has two pose solutions (:func:`~stackpick_sim.vision.pose.
circle_poses`). Each predicts where the cylinder's side wall shows: the band swept by the rim
moving into the object along the face normal, outside the face ellipse. The wall is the same
material as the face, so in the image it has the face's hue (chromaticity); its brightness
differs: the ring light at the camera meets it obliquely, so it is darker than the face, at
most about tan(tilt) of it (``band_brightness_margin``). A sample counts as wall when it has the
face's hue at a wall's brightness. On the wrong solution's side the band falls on the grey
belt or on another object; a lower face of the same colour passes the hue test but is about
as bright as the face, which no wall of a face tilted < 45 deg is. A grey object's wall has
the belt's hue too: given the bare belt's colour, a sample that has it (``band_belt_delta``)
is not wall either (on the coloured objects of the paper's scenes the hue test already
rejects it). The test's settings are the ``band_*`` fields of
:class:`~stackpick_sim.config.vision_params.PoseParams`.

The solution whose predicted band matches better resolves the two-fold tilt ambiguity
(:mod:`stackpick_sim.vision.pose`). (Not used: calling a face whose best band is mostly not
its colour "leaned on", hence not top; on rendered paper-scene frames free walls and covered
ones overlap, since a leaning neighbour of the same colour passes the hue test.)

The band's image does not depend on the face radius (the whole solution scales with it), so
unit-radius solutions are used throughout.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import PoseParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision import kernels, kernels_pose
from stackpick_sim.vision.contrast import unit_circle

#: Rim points per depth.
WALL_RIM_POINTS = 32
#: The default settings of the band (``wall_depths``, ``wall_margin_px``) and of its colour
#: test (the ``band_*`` fields of PoseParams: the reasons for each).
DEFAULT_POSE = PoseParams()
#: Interior points whose median colour is the face's colour, at this share of the semi-axes.
FACE_SAMPLE_SCALE = 0.5
#: Interior sample count.
FACE_SAMPLES = 16
#: unit_circle(FACE_SAMPLES), writable: the compiled pass's argument type.
_FACE_CIRCLE = tuple(t.copy() for t in unit_circle(FACE_SAMPLES))


def plane_basis(normal: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`stackpick_sim.geometry.plane_basis` (same vectors) on scalars
    (:func:`~stackpick_sim.vision.kernels_pose.plane_axes`): numpy's ``cross`` costs ~20 us
    a call."""
    u, v = _basis(normal)
    return np.array(u), np.array(v)


def _basis(normal: NDArray[np.float64]) -> tuple[tuple[float, float, float],
                                                 tuple[float, float, float]]:
    """:func:`plane_basis` as float triples."""
    # The wall bands' compiled axes (kernels_pose.plane_axes): one copy of the arithmetic, a
    # call costing what the same arithmetic on Python floats does.
    u0, u1, u2, v0, v1, v2 = kernels_pose.plane_axes(*_floats(normal))
    return (u0, u1, u2), (v0, v1, v2)


def _floats(vector: NDArray[np.float64]) -> list[float]:
    """A 3-vector's components as Python floats (``tolist`` of an array: a tenth of the cost
    of iterating over its numpy scalars; the same values)."""
    values = vector.tolist() if isinstance(vector, np.ndarray) else vector
    return [float(x) for x in values]


def column_median(values: NDArray) -> NDArray[np.float64]:
    """Median of each column of an (N, ...) array, N >= 1: ``np.median(values, axis=0)``
    from one sort (numpy's median costs ~10x more on the few values read here)."""
    ordered = np.sort(np.asarray(values, np.float64), axis=0)
    n = ordered.shape[0]
    return np.asarray(0.5 * (ordered[(n - 1) // 2] + ordered[n // 2]), np.float64)


@dataclass(frozen=True, kw_only=True)
class WallEvidence:
    """Band samples a solution predicts outside the face (``samples``) and the share of them
    showing the face's hue (``share``, 0-1; 0 when there are no samples)."""

    samples: int
    share: float


def face_colour(ellipse: Ellipse, image: NDArray[np.uint8],
                scale: float = FACE_SAMPLE_SCALE) -> NDArray[np.float64]:
    """(3,) median colour of FACE_SAMPLES points inside ``ellipse`` of an (H, W, 3) image, on
    the ellipse of ``scale`` times its semi-axes."""
    th = math.radians(ellipse.angle_deg)
    c, s = math.cos(th), math.sin(th)
    # The sample pixels (cx + c x) - s y and (cy + s x) + c y, rounded and clamped into the
    # image, and each channel's median from a sort of its integer values, in one compiled
    # pass (kernels.face_median: the same values as the array form).
    pixels = image if image.ndim == 3 else image[:, :, None]
    colour = kernels.face_median(kernels.kernel_array(pixels), ellipse.cx,
                                 ellipse.cy, scale * ellipse.a, scale * ellipse.b, c, s,
                                 *_FACE_CIRCLE)
    return colour if image.ndim == 3 else np.asarray(colour[0], np.float64)


def band_points(normal_cam: NDArray[np.float64], centre_cam: NDArray[np.float64],
                ellipse: Ellipse, intrinsics: CameraIntrinsics,
                depths: tuple[float, ...] = DEFAULT_POSE.wall_depths,
                margin_px: float = DEFAULT_POSE.wall_margin_px) -> NDArray[np.float64]:
    """(N, 2) pixels (u, v) of the predicted wall band more than ``margin_px`` outside
    ``ellipse``.

    ``normal_cam`` (3,) is the inward unit face normal and ``centre_cam`` (3,) the centre of a
    unit-radius face, camera frame (a unit-radius :class:`~stackpick_sim.vision.pose.
    CirclePose`); ``depths`` the sampled depths along the axis, in face radii.
    """
    pu, pv, keep = solution_bands([(normal_cam, centre_cam)], ellipse, intrinsics, depths,
                                  margin_px)
    pts = np.empty((int(np.count_nonzero(keep)), 2))
    pts[:, 0], pts[:, 1] = pu[keep], pv[keep]
    return pts


def solution_bands(solutions: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
                   faces: Ellipse | Sequence[Ellipse], intrinsics: CameraIntrinsics,
                   depths: tuple[float, ...] = DEFAULT_POSE.wall_depths,
                   margin_px: float = DEFAULT_POSE.wall_margin_px
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The predicted wall bands of S unit-radius solutions (normal_cam (3,), centre_cam (3,),
    as in :func:`band_points`) of one face ellipse, or each of the face ``faces[s]``
    (parallel), in one array pass: pixels u, v (S, P) of every band point (P = len(depths) x
    WALL_RIM_POINTS, depth by depth; (S * P,) for one face ellipse) and which of them lie
    more than ``margin_px`` outside the solution's face."""
    band = solution_band_points(solutions, depths)
    # One face: flat rows (its terms are scalars; numpy broadcasts them at less cost).
    return _project_outside(band.reshape(3, -1) if isinstance(faces, Ellipse) else band,
                            faces, intrinsics, margin_px)


def solution_band_points(solutions: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
                         depths: tuple[float, ...] = DEFAULT_POSE.wall_depths
                         ) -> NDArray[np.float64]:
    """(3, S, P) camera-frame points of the wall bands of S unit-radius solutions
    (normal_cam (3,), centre_cam (3,)): P = len(depths) x WALL_RIM_POINTS, depth by depth,
    the rim at each depth (in face radii) along the normal."""
    ct, st = unit_circle(WALL_RIM_POINTS)
    # The rims' axes and the rims at each depth in one compiled pass (kernels_pose.
    # band_points_of: the same arithmetic as plane_basis and the array form centre + ct u +
    # st v + depth normal).
    return kernels_pose.band_points_of(_solution_array(solutions), ct, st, _depths(depths))


def _solution_array(solutions: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]]
                    ) -> NDArray[np.float64]:
    """S (normal_cam (3,), centre_cam (3,)) pairs as one fresh (S, 2, 3) float64 array."""
    return np.array(solutions, np.float64).reshape(-1, 2, 3)


@functools.lru_cache(maxsize=16)
def _depths(depths: tuple[float, ...]) -> NDArray[np.float64]:
    """``depths`` as a float64 array (cached: a few tuples, asked for many times a frame)."""
    out = np.asarray(depths, np.float64)
    out.setflags(write=False)
    return out


def _project_outside(band: NDArray[np.float64], faces: Ellipse | Sequence[Ellipse],
                     intrinsics: CameraIntrinsics, margin_px: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The pixels u, v (S, P) of the (3, S, P) camera-frame points ``band`` and which of them
    lie more than ``margin_px`` outside ``faces[s]`` (one per row s); for one face ellipse,
    the same of (3, N) points."""
    # Radial distance outside the ellipse, px (exact on circles, close on squat ellipses),
    # in one compiled pass (kernels.project_outside: the same arithmetic as the array form).
    one = isinstance(faces, Ellipse)
    points = kernels.kernel_array(band.reshape(3, 1, -1) if one else band, np.float64)
    terms = np.array([_terms(faces)] if isinstance(faces, Ellipse)
                     else [_terms(e) for e in faces], np.float64).reshape(-1, 6)
    pu, pv, outside = kernels.project_outside(points, terms, intrinsics.fx, intrinsics.fy,
                                              intrinsics.cx, intrinsics.cy, margin_px)
    if one:
        return pu[0], pv[0], outside[0]
    return pu, pv, outside


def _terms(e: Ellipse) -> tuple[float, float, float, float, float, float]:
    """(cx, cy, cos angle, sin angle, a, b) of an ellipse."""
    th = math.radians(e.angle_deg)
    return e.cx, e.cy, math.cos(th), math.sin(th), e.a, e.b


def wall_evidence(normal_cam: NDArray[np.float64], centre_cam: NDArray[np.float64],
                  ellipse: Ellipse, intrinsics: CameraIntrinsics, image: NDArray[np.uint8],
                  face: NDArray[np.float64] | None = None,
                  belt: NDArray[np.float64] | None = None,
                  params: PoseParams = DEFAULT_POSE) -> WallEvidence:
    """Wall evidence of one unit-radius solution in an (H, W, 3) RGB or (H, W) gray image.

    ``face`` is the face's colour if already known (see :func:`face_colour`); ``belt`` the
    bare belt's colour (one value per channel; :attr:`~stackpick_sim.vision.roi.Roi.belt`):
    a sample within ``params.band_belt_delta`` of it is belt. On a gray image, or a grey
    object's, every sample has the face's "hue", so only the brightness floor and the belt's
    colour tell belt from wall. The test itself is :func:`band_evidences`' (one copy for
    every caller).
    """
    colour = face_colour(ellipse, image) if face is None else face
    return wall_evidences([(normal_cam, centre_cam)], ellipse, intrinsics, image,
                          np.asarray(colour, np.float64), belt, params)[0]


def wall_evidences(solutions: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
                   ellipse: Ellipse, intrinsics: CameraIntrinsics, image: NDArray[np.uint8],
                   face: NDArray[np.float64], belt: NDArray[np.float64] | None = None,
                   params: PoseParams = DEFAULT_POSE) -> list[WallEvidence]:
    """:func:`wall_evidence` of each unit-radius solution (normal_cam (3,), centre_cam (3,))
    of ``ellipse``, in one array pass (the same results); ``face`` is the face's colour,
    ``belt`` the bare belt's (or None); the band's depths and margin are ``params``'
    (``wall_depths``, ``wall_margin_px``)."""
    # The bands, their pixels outside the face and the colour test, in one compiled pass
    # (kernels_pose.wall_hits: solution_bands, then band_evidences' test, the same
    # arithmetic).
    pixels = image if image.ndim == 3 else image[:, :, None]
    pixels = kernels.kernel_array(pixels)
    c = pixels.shape[2]
    ct, st = unit_circle(WALL_RIM_POINTS)
    colour = _per_channel(face, c)
    # Without a belt colour the pass does not read it: the face's stands in.
    belt_colour = colour if belt is None else _per_channel(belt, c)
    counts, hits = kernels_pose.wall_hits(
        _solution_array(solutions), ct, st, _depths(params.wall_depths), _terms(ellipse),
        (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy), params.wall_margin_px,
        pixels, colour, (params.band_brightness_margin, params.band_chroma_tolerance,
                         params.band_min_brightness, params.band_belt_delta),
        belt_colour, belt is not None)
    return _evidences(counts, hits)


def band_evidences(pu: NDArray[np.float64], pv: NDArray[np.float64], keep: NDArray[np.bool_],
                   image: NDArray[np.uint8], colours: NDArray[np.float64],
                   tans: Sequence[float], belt: NDArray[np.float64] | None = None,
                   params: PoseParams = DEFAULT_POSE) -> list[WallEvidence]:
    """Per solution, the :func:`wall_evidence` test on band pixels already predicted: row s
    of the (S, P) pixels ``pu``, ``pv`` and of ``keep`` (which lie outside the face) is
    solution s's band, ``colours`` (S, C) its face's colour in the (H, W, C) or (H, W)
    ``image`` and ``tans`` (S,) its :func:`tan_tilt`; ``belt`` the bare belt's colour (C,)
    or None; ``params``: the test's ``band_*`` settings. Band pixels off the image are not
    samples. One array pass for every solution, of one face or of several."""
    # One compiled pass (kernels.band_hits: the same tests and sums as the array form).
    def rows(a: NDArray) -> NDArray:  # C order and writable: the compiled argument types
        return kernels.kernel_array(a)

    pixels = image if image.ndim == 3 else image[:, :, None]
    c = pixels.shape[2]
    counts, hits = kernels.band_hits(
        rows(pu), rows(pv), rows(keep), rows(pixels),
        rows(np.broadcast_to(np.asarray(colours, np.float64), (keep.shape[0], c))),
        np.asarray(tans, np.float64) + params.band_brightness_margin,
        np.zeros(c) if belt is None else rows(np.broadcast_to(
            np.asarray(belt, np.float64).reshape(-1), (c,))),
        belt is not None, params.band_chroma_tolerance, params.band_min_brightness,
        params.band_belt_delta)
    return _evidences(counts, hits)


def _per_channel(colour: NDArray[np.float64], channels: int) -> NDArray[np.float64]:
    """A colour (one value per channel, or one for all) as a (channels,) float64 array the
    compiled pass takes (C order, writable; ``colour`` itself where it is one)."""
    if (type(colour) is np.ndarray and colour.shape == (channels,)
            and colour.dtype == np.float64 and colour.flags.c_contiguous
            and colour.flags.writeable):
        return colour
    flat = np.asarray(colour, np.float64).reshape(-1)
    if flat.shape[0] != channels:
        return np.broadcast_to(flat, (channels,)).copy()
    return kernels.kernel_array(flat)


def _evidences(counts: NDArray[np.int64], hits: NDArray[np.float64]) -> list[WallEvidence]:
    """The WallEvidence of each band from its sample ``counts`` and ``hits``."""
    return [WallEvidence(samples=int(n), share=float(k / n) if n else 0.0)
            for n, k in zip(counts.tolist(), hits.tolist(), strict=True)]


def tan_tilt(normal_cam: NDArray[np.float64], centre_cam: NDArray[np.float64]) -> float:
    """tan of the angle between the face normal and the viewing ray to the face centre."""
    # Three-vectors: Python floats (numpy's norm and dot cost more than the arithmetic).
    c0, c1, c2 = _floats(centre_cam)
    n0, n1, n2 = _floats(normal_cam)
    c_norm = max(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-12)
    n_norm = max(math.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-12)
    cos_tilt = min(1.0, abs((n0 * c0 + n1 * c1 + n2 * c2) / c_norm) / n_norm)
    return math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt)) / max(cos_tilt, 1e-6)
