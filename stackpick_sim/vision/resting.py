"""Which whole face's object rests on which: a contact test of the reconstructed cylinders.

The image rules (T-junctions on face outlines, :mod:`~stackpick_sim.vision.wall_cover` on
side walls) see an object lying on another only where one covers the other in the image. A
cylinder leaning on another's side wall, below that one's face, covers little or nothing of
it: both faces show whole, with no T-junction, and the leaning one's face can be the farther
from the camera (in the paper scene, a small cylinder tilted 42 deg leaning its far rim on a
large one's wall: faces 2 mm apart in depth). The ground truth calls the leaned-on object not
top: a contact whose normal points up (z >= 0.3) into another object.

That contact can be read from the 3-D reconstruction instead. Each whole face gives its
cylinder: the pose solution its wall band favours (:func:`~stackpick_sim.vision.pose.
choose_by_band`), the radius from its colour, the axis along the inward normal for its kind's
height (the caller's, from the scene's object kinds). For two convex bodies the largest
separation along a direction,
``max_d (min_{x in A} x.d - max_{x in B} x.d)``, is their distance when apart and minus their
penetration depth when overlapping, and the maximising ``d`` is the contact normal from B to A
(the separating axis); a cylinder's support function is closed-form, so the maximum is taken
over a fixed set of directions, all pairs in one array pass. When the bodies touch (within
the top rule's ``rest_contact_gap_m`` .. ``rest_max_penetration_m``) and the normal points up
(UP_CAM) by ``rest_min_up`` or more, A rests on B (settings: :class:`~stackpick_sim.config.
vision_params.TopParams`). A face seen square on (neither solution's band visible) takes the smaller
tilt, as the pose does. A face whose visible bands cannot tell its solution can be found
under another face (``rest_untold_solutions``: the leaning object often hides the band that
would tell), when the combinations of its solutions that find a rest all find that one; it
is no evidence as the upper face.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.vision_params import PoseParams, TopParams
from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.pose import (
    CirclePose,
    choose_by_band,
    unit_circle_poses,
)
from stackpick_sim.vision.wall import (
    WALL_RIM_POINTS,
    WallEvidence,
    band_evidences,
    face_colour,
    tan_tilt,
)
from stackpick_sim.vision.wall_cover import BandCache, CoverCheck, face_bands

#: The top rule's default settings (the contact gap, penetration and upward share).
DEFAULT_TOP = TopParams()
#: The pose's default settings (its wall band test and the band choice).
DEFAULT_POSE = PoseParams()
#: World up in the camera frame: the look pose looks straight down (OpenCV axes, +z forward).
UP_CAM = np.array([0.0, 0.0, -1.0])
#: Directions searched for the separating axis (a Fibonacci sphere): ~3 deg apart, so the
#: normal's upward component is off by < 0.06 and a touching pair's separation reads up to
#: ~1.5 mm negative (a face of 0.035 m radius seen ~2 deg off its normal).
AXIS_DIRECTIONS = 4000


@functools.lru_cache(maxsize=1)
def _directions(n: int = AXIS_DIRECTIONS) -> NDArray[np.float64]:
    """(n, 3) unit vectors spread evenly over the sphere (read-only)."""
    k = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * k / n)
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * k
    d = np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                  np.cos(polar)], axis=1)
    d.setflags(write=False)
    return d


def _support(centre: NDArray[np.float64], normal: NDArray[np.float64], radius: NDArray[np.float64],
             height: NDArray[np.float64], dirs: NDArray[np.float64]) -> NDArray[np.float64]:
    """(P, D) support function max_x x.d of P cylinders (face centre (P, 3) m, inward unit
    axis (P, 3), radius (P,) m, height (P,) m) over directions (D, 3)."""
    nd = normal @ dirs.T
    return (centre @ dirs.T + np.maximum(0.0, height[:, None] * nd)
            + radius[:, None] * np.sqrt(np.maximum(0.0, 1.0 - nd * nd)))


def contact(centres: NDArray[np.float64], normals: NDArray[np.float64],
            radii: NDArray[np.float64], heights: NDArray[np.float64], pairs: NDArray[np.int64]
            ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Separation (P,) m (negative: penetration) and contact normal (P, 3) from body
    ``pairs[:, 1]`` to body ``pairs[:, 0]`` of cylinders given by face centre (N, 3) m, inward
    unit axis (N, 3), radius (N,) m and height (N,) m, camera frame; see the module
    docstring."""
    dirs, opposite = _direction_set(coarse=False)
    sep = _separations(centres, normals, radii, heights, pairs, dirs, opposite)
    best = np.argmax(sep, axis=1)
    return sep[np.arange(len(pairs)), best], dirs[best]


def _separations(centres: NDArray[np.float64], normals: NDArray[np.float64],
                 radii: NDArray[np.float64], heights: NDArray[np.float64],
                 pairs: NDArray[np.int64], dirs: NDArray[np.float64],
                 opposite: NDArray[np.float64]) -> NDArray[np.float64]:
    """(P, D) separation of each pair's bodies (as :func:`contact`'s) along each of the
    directions ``dirs`` (D, 3) (``opposite``: ``-dirs``)."""
    a, b = pairs[:, 0], pairs[:, 1]
    return np.asarray(-_support(centres[a], normals[a], radii[a], heights[a], opposite)
                      - _support(centres[b], normals[b], radii[b], heights[b], dirs))


#: Every this many of the separating-axis directions form the coarse set of the cost gate in
#: :func:`rests_on`: a pair apart along one of them by more than the contact gap does not touch
#: (the separation is a maximum over the directions, so a subset's is a lower bound). On 200
#: rendered paper-scene frames this rules out 62 of 114 candidate face pairs whichever their
#: pose solutions, and every pair of 44 of the 87 calls.
COARSE_EVERY = 16


@functools.lru_cache(maxsize=2)
def _direction_set(coarse: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`_directions`, or every COARSE_EVERY-th of them (contiguous), and their
    opposites (read-only)."""
    dirs = np.ascontiguousarray(_directions()[::COARSE_EVERY] if coarse else _directions())
    opposite = -dirs
    dirs.setflags(write=False)
    opposite.setflags(write=False)
    return dirs, opposite


def rests_on(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
             radius_of: Callable[[Ellipse], float | None],
             height_of: Callable[[float], float | None], image: NDArray[np.uint8], *,
             colour_of: Callable[[Ellipse], NDArray[np.float64]] | None = None,
             cache: BandCache | None = None,
             belt: NDArray[np.float64] | None = None,
             params: TopParams = DEFAULT_TOP, pose_params: PoseParams = DEFAULT_POSE
             ) -> list[bool]:
    """Per face (whole faces of an (H, W, 3) RGB image, pixel frame of ``intrinsics``): does
    another face's cylinder rest on its cylinder (see the module docstring). ``radius_of``:
    a face's radius (m); ``height_of``: the cylinder height (m) of a radius; a face for which
    either gives None takes no part. The true height matters: one 5 mm too tall flips the
    contact normal of a lean on a far rim.
    ``colour_of``: a face's colour in ``image`` (:func:`~stackpick_sim.vision.wall.
    face_colour`), when the caller keeps them; ``cache``: the wall bands the cover test
    computed (:func:`~stackpick_sim.vision.wall_cover.face_bands`); ``belt``: the bare
    belt's colour for the wall test (:func:`~stackpick_sim.vision.wall.band_evidences`);
    ``params``: the contact settings (``rest_*``); ``pose_params``: the wall band test's and
    the band choice's (as the pose's)."""
    bodies = _bodies(faces, intrinsics, radius_of, height_of)
    if bodies is None:
        return [False] * len(faces)
    return _rests(faces, bodies, _coarse_separations(bodies), intrinsics, image,
                  (colour_of, cache, belt), (params, pose_params))


def _rests(faces: Sequence[Ellipse], bodies: _Bodies,
           coarse: tuple[list[tuple[int, int]], NDArray[np.float64]],
           intrinsics: CameraIntrinsics, image: NDArray[np.uint8],
           seen: tuple[Callable[[Ellipse], NDArray[np.float64]] | None,
                       BandCache | None, NDArray[np.float64] | None],
           settings: tuple[TopParams, PoseParams]) -> list[bool]:
    """:func:`rests_on` given the faces' ``bodies`` and their :func:`_coarse_separations`
    ``coarse``; ``seen``: its ``colour_of``, ``cache`` and ``belt``; ``settings``: its
    ``params`` and ``pose_params``."""
    colour_of, cache, belt = seen
    params, pose_params = settings
    under = [False] * len(faces)
    near, apart = _touching_pairs(*coarse, params.rest_contact_gap_m)
    if not near:
        return under
    picks = _solution_picks(faces, bodies, sorted({p for pq in near for p in pq}),
                            intrinsics, image, colour_of, cache, belt, pose_params)
    # The chosen solutions' pairs not already apart along the coarse directions.
    todo = [(p, q) for p, q in near if p in picks and q in picks
            and not apart[(p, q)][picks[p]][picks[q]]]
    for _upper, lower in _resting_pairs(bodies, picks, todo, params):
        under[bodies.kinds[lower][0]] = True
    if params.rest_untold_solutions:
        for lower in _untold_rests(bodies, picks, near, apart, params):
            under[bodies.kinds[lower][0]] = True
    return under


def _untold_rests(bodies: _Bodies, picks: dict[int, int], near: list[tuple[int, int]],
                  apart: dict[tuple[int, int], list[list[bool]]], params: TopParams
                  ) -> list[int]:
    """The lower bodies (indices into ``bodies.kinds``) of the ``near`` pairs with a face
    whose wall bands cannot tell its pose solution (not in ``picks``), found resting under
    its solutions (``rest_untold_solutions``): every combination of the untold faces'
    solutions (the told face's own) not ``apart`` is tried, and a rest counts when those
    that find one all find it one way, the untold face the lower (the failure class *a whole
    lower face chosen over the face leaning on it, its solution untold*: the leaning object
    hides the wall band that would tell the lower face's solution)."""
    lowers = []
    for p, q in near:
        if p in picks and q in picks:
            continue
        combos = [(j, k) for j in _solutions(picks, p) for k in _solutions(picks, q)
                  if not apart[(p, q)][j][k]]
        found = {pair for j, k in combos
                 for pair in _resting_pairs(bodies, {p: j, q: k}, [(p, q)], params)}
        lower = found.pop()[1] if len(found) == 1 else None
        if lower is not None and lower not in picks:
            # Only the face leaned on: the leaning object hides the band that would tell
            # its solution; an untold upper face's contact is no evidence.
            lowers.append(lower)
    return lowers


def _solutions(picks: dict[int, int], p: int) -> tuple[int, ...]:
    """Body ``p``'s pose solutions to try: its pick, else both."""
    return (picks[p],) if p in picks else (0, 1)


def rests_on_any_kind(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
                      radii: Sequence[float], height_of: Callable[[float], float | None],
                      image: NDArray[np.uint8], *,
                      colour_of: Callable[[Ellipse], NDArray[np.float64]] | None = None,
                      cache: BandCache | None = None,
                      belt: NDArray[np.float64] | None = None,
                      params: TopParams = DEFAULT_TOP, pose_params: PoseParams = DEFAULT_POSE,
                      kinds_of: Callable[[Ellipse], tuple[float, ...]] | None = None
                      ) -> list[bool]:
    """:func:`rests_on` of faces whose kind is unknown (kinds of one colour: the failure
    class *lean on a whole face, kinds that colour cannot tell apart*). Each pair of faces is
    reconstructed under every assignment of the kinds' ``radii`` to its two faces: a face is
    under the other when the other rests on it under some assignment, and under every other
    assignment the two bodies are apart by more than ``params.rest_kind_margin_m`` or run
    through each other (an impossible assignment). A wrong radius moves a face's cylinder
    along its rays by the radii's ratio, centimetres at the camera's distance, so a wrong
    assignment's bodies are far apart; but scaling both faces alike moves the pair nearly as
    a whole, and such an assignment near contact leaves the pair undecided. With
    ``kinds_of`` (a face's admitted radii, :mod:`~stackpick_sim.vision.kind_size`), each face
    takes only those of ``radii``."""
    under = [False] * len(faces)
    kinds = [r for r in radii if height_of(r) is not None]
    admitted = [kinds if kinds_of is None else [r for r in kinds if r in kinds_of(face)]
                for face in faces]
    settings = (params, pose_params)
    for p, q in itertools.combinations(range(len(faces)), 2):
        pair = (faces[p], faces[q])
        verdicts = [_pair_verdict(pair, intrinsics, dict(zip(pair, assigned, strict=True)).get,
                                  height_of, image, (colour_of, cache, belt), settings)
                    for assigned in itertools.product(admitted[p], admitted[q])]
        rests = {v for v in verdicts if v is not None and v >= 0}
        if len(rests) == 1 and None not in verdicts:
            under[(p, q)[rests.pop()]] = True
    return under


def rest_test(intrinsics: CameraIntrinsics, radius_of: Callable[[Ellipse], float | None] | None,
              radii: Sequence[float], height_of: Callable[[float], float | None],
              image: NDArray[np.uint8], *,
              colour_of: Callable[[Ellipse], NDArray[np.float64]] | None = None,
              cache: BandCache | None = None, belt: NDArray[np.float64] | None = None,
              params: TopParams = DEFAULT_TOP, pose_params: PoseParams = DEFAULT_POSE,
              kinds_of: Callable[[Ellipse], tuple[float, ...]] | None = None
              ) -> Callable[[Sequence[Ellipse]], list[bool]] | None:
    """The top rule's rest test on a list of faces, per face whether another face's cylinder
    rests on its own: :func:`rests_on` with ``radius_of`` (radii from colour), else
    :func:`rests_on_any_kind` over ``radii`` when they hold two kinds or more; None with
    neither (a face's kind is then unknown and no assignment of radii can be weighed)."""
    if radius_of is not None:
        known = radius_of
        return lambda faces: rests_on(faces, intrinsics, known, height_of, image,
                                      colour_of=colour_of, cache=cache, belt=belt,
                                      params=params, pose_params=pose_params)
    if len(radii) < 2:
        return None
    return lambda faces: rests_on_any_kind(faces, intrinsics, radii, height_of, image,
                                           colour_of=colour_of, cache=cache, belt=belt,
                                           params=params, pose_params=pose_params,
                                           kinds_of=kinds_of)


def _pair_verdict(pair: tuple[Ellipse, Ellipse], intrinsics: CameraIntrinsics,
                  radius_of: Callable[[Ellipse], float | None],
                  height_of: Callable[[float], float | None], image: NDArray[np.uint8],
                  seen: tuple[Callable[[Ellipse], NDArray[np.float64]] | None,
                              BandCache | None, NDArray[np.float64] | None],
                  settings: tuple[TopParams, PoseParams]) -> int | None:
    """For :func:`rests_on_any_kind`, the two faces' cylinders of one assignment of radii
    (``radius_of``): the index (0, 1) of the face the other rests on; -1 when they are apart
    by more than the margin, run through each other, or their solutions are not told; None
    when they come nearer without a rest (undecided). ``seen``: :func:`rests_on`'s
    ``colour_of``, ``cache`` and ``belt``; ``settings``: its ``params`` and
    ``pose_params``."""
    params = settings[0]
    bodies = _bodies(pair, intrinsics, radius_of, height_of)
    if bodies is None:
        return -1
    coarse = _coarse_separations(bodies)
    found = _rests(pair, bodies, coarse, intrinsics, image, seen, settings)
    if any(found):
        return found.index(True)
    sep = coarse[1]
    near = (sep <= params.rest_kind_margin_m) & (sep >= -params.rest_max_penetration_m)
    return None if bool(near.any()) else -1


def cover_check(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
                radius_of: Callable[[Ellipse], float | None],
                height_of: Callable[[float], float | None],
                params: TopParams = DEFAULT_TOP) -> CoverCheck:
    """The :data:`~stackpick_sim.vision.wall_cover.CoverCheck` of the reconstructed
    cylinders of ``faces``: pose solution s of face i can lie under face j unless its
    cylinder runs deeper than ``params.rest_max_penetration_m`` into face j's, whichever j's
    solution (an object whose wall another face covers is under it, not through it), while
    i's other solution's does not (the solids then tell i's solution; when both run through
    j's, a fit is wrong and the solids tell nothing); possible wherever a kind is unknown."""

    def possible(triples: list[tuple[int, int, int]]) -> list[bool]:
        # The cylinders only when a cover is found (under_another calls this at most once).
        bodies = _bodies(faces, intrinsics, radius_of, height_of)
        row = ({} if bodies is None
               else {face: p for p, (face, _, _) in enumerate(bodies.kinds)})
        known = [(i, s, j) for i, s, j in triples if i in row and j in row]
        if bodies is None or not known:
            return [True] * len(triples)
        # Per triple: (this solution, the other) x (j's two solutions).
        pairs = np.array([(2 * row[i] + (s ^ other), 2 * row[j] + t) for i, s, j in known
                          for other in (0, 1) for t in (0, 1)], np.int64)
        least = -params.rest_max_penetration_m
        if _clear_on_coarse(bodies, pairs, least):
            return [True] * len(triples)
        sep = contact(bodies.centres, bodies.normals, bodies.radii, bodies.heights, pairs)[0]
        clear = (sep.reshape(-1, 2, 2).max(axis=2) >= least).tolist()
        verdict = {t: this or not other for t, (this, other) in zip(known, clear, strict=True)}
        return [verdict.get(t, True) for t in triples]

    return possible


#: Slack (m) of :func:`_clear_on_coarse`: far beyond the rounding of a separation (~1e-16 m
#: on these sizes), far below any setting's scale (millimetres).
COARSE_SCREEN_SLACK_M = 1e-9


def _clear_on_coarse(bodies: _Bodies, pairs: NDArray[np.int64], least: float) -> bool:
    """Whether :func:`cover_check`'s verdicts are all "possible" on the coarse directions
    alone: for every triple (its four rows of ``pairs``: this solution's two, then the other
    solution's), this solution's cylinder is apart from face j's, or runs into it by less
    than ``-least``, along some coarse direction for one of j's solutions (by
    COARSE_SCREEN_SLACK_M). The separation is a maximum over the directions, which hold the
    coarse ones, so the exact test finds it clear too; the exact test is spared (a cover the
    solids allow is the common case)."""
    coarse = _separations(bodies.centres, bodies.normals, bodies.radii, bodies.heights, pairs,
                          *_direction_set(coarse=True)).max(axis=1)
    this = coarse.reshape(-1, 2, 2)[:, 0, :].max(axis=1)
    return bool(np.all(this >= least + COARSE_SCREEN_SLACK_M))


@dataclass(frozen=True, kw_only=True)
class _Bodies:
    """Both pose solutions' cylinders of the faces of known kind: ``kinds`` (face index,
    radius m, height m), ``units`` each face's unit-radius pose solutions, and per solution
    (rows 2p, 2p + 1: ``kinds[p]``'s) the face centre (2P, 3) m, inward unit axis (2P, 3),
    radius (2P,) m and height (2P,) m, camera frame."""

    kinds: list[tuple[int, float, float]]
    units: list[tuple[CirclePose, CirclePose]]
    centres: NDArray[np.float64]
    normals: NDArray[np.float64]
    radii: NDArray[np.float64]
    heights: NDArray[np.float64]


def _bodies(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
            radius_of: Callable[[Ellipse], float | None],
            height_of: Callable[[float], float | None]) -> _Bodies | None:
    """The cylinders of the faces whose radius and height are known, or None for fewer than
    two such faces."""
    kinds = _known_kinds(faces, radius_of, height_of)
    if len(kinds) < 2:
        return None
    units = [unit_circle_poses(faces[i], intrinsics) for i, _, _ in kinds]
    return _Bodies(
        kinds=kinds, units=units,
        centres=np.array([s.centre_cam * radius for (_, radius, _), unit
                          in zip(kinds, units, strict=True) for s in unit]),
        normals=np.array([s.normal_cam for unit in units for s in unit]),
        radii=np.array([radius for _, radius, _ in kinds for _ in range(2)]),
        heights=np.array([height for _, _, height in kinds for _ in range(2)]))


def _known_kinds(faces: Sequence[Ellipse], radius_of: Callable[[Ellipse], float | None],
                 height_of: Callable[[float], float | None]) -> list[tuple[int, float, float]]:
    """(face index, radius m, height m) of each face whose kind's radius and height are
    known."""
    kinds: list[tuple[int, float, float]] = []
    for i, face in enumerate(faces):
        radius = radius_of(face)
        height = None if radius is None else height_of(radius)
        if radius is not None and height is not None:
            kinds.append((i, radius, height))
    return kinds


def _coarse_separations(bodies: _Bodies
                        ) -> tuple[list[tuple[int, int]], NDArray[np.float64]]:
    """The pairs (p, q), p < q, of ``bodies.kinds``, and (P, 2, 2) their separations (m)
    along the coarse directions for each combination of their solutions ([j][k]: p's j,
    q's k): a lower bound of the true separation."""
    n = len(bodies.kinds)
    face_pairs = [(p, q) for p in range(n) for q in range(p + 1, n)]
    combos = np.array([(2 * p + j, 2 * q + k) for p, q in face_pairs for j in (0, 1)
                       for k in (0, 1)], np.int64)
    sep = _separations(bodies.centres, bodies.normals, bodies.radii, bodies.heights, combos,
                       *_direction_set(coarse=True)).max(axis=1)
    return face_pairs, sep.reshape(-1, 2, 2)


def _touching_pairs(face_pairs: list[tuple[int, int]], sep: NDArray[np.float64], gap_m: float
                    ) -> tuple[list[tuple[int, int]], dict[tuple[int, int], list[list[bool]]]]:
    """The cost gate, before the wall bands choose the solutions: of ``face_pairs`` and
    their :func:`_coarse_separations` ``sep``, the pairs that may touch, and for each pair,
    whether each combination of their solutions is apart by more than ``gap_m`` (pairs
    apart whichever their solutions do not touch; on rendered paper-scene frames about half
    the calls have no other pair)."""
    apart = (sep > gap_m).tolist()
    gaps = dict(zip(face_pairs, apart, strict=True))
    return [pq for pq in face_pairs if not all(gaps[pq][0] + gaps[pq][1])], gaps


def _solution_picks(faces: Sequence[Ellipse], bodies: _Bodies, involved: list[int],
                    intrinsics: CameraIntrinsics, image: NDArray[np.uint8],
                    colour_of: Callable[[Ellipse], NDArray[np.float64]] | None,
                    cache: BandCache | None, belt: NDArray[np.float64] | None,
                    params: PoseParams) -> dict[int, int]:
    """The pose solution (0 or 1) of each ``involved`` body (indices into ``bodies.kinds``)
    its wall bands favour (:func:`~stackpick_sim.vision.pose.choose_by_band`); a face seen
    square on (no band shows) takes the smaller tilt; a face whose bands cannot tell has
    none."""
    picks: dict[int, int] = {}
    evidence = wall_evidences_of([faces[bodies.kinds[p][0]] for p in involved],
                                 intrinsics, image, colour_of, cache, belt, params)
    for p, bands in zip(involved, evidence, strict=True):
        pick = choose_by_band(bands, params)
        if pick is None and all(b.samples < params.min_band_samples for b in bands):
            # Seen square on, no wall shows and the two solutions nearly coincide: the
            # smaller tilt, as the pose takes (a flat face another object leans on).
            pick = int(np.argmax([float(s.normal_cam[2]) for s in bodies.units[p]]))
        if pick is not None:
            picks[p] = pick
    return picks


def _resting_pairs(bodies: _Bodies, picks: dict[int, int], todo: list[tuple[int, int]],
                   params: TopParams) -> list[tuple[int, int]]:
    """Of the pairs ``todo`` (with their ``picks``' solutions): (upper, lower) for each
    pair in contact (within ``params.rest_contact_gap_m`` .. ``rest_max_penetration_m``)
    whose contact normal points up by ``rest_min_up`` or more, one way or the other."""
    if not todo:
        return []
    sep, normal = contact(bodies.centres, bodies.normals, bodies.radii, bodies.heights,
                         np.array([(2 * p + picks[p], 2 * q + picks[q]) for p, q in todo],
                                  np.int64))
    up = normal @ UP_CAM
    touching = (sep <= params.rest_contact_gap_m) & (sep >= -params.rest_max_penetration_m)
    min_up = params.rest_min_up
    out = []
    for (p, q), t, u in zip(todo, touching.tolist(), up.tolist(), strict=True):
        if t and u >= min_up:
            out.append((p, q))
        elif t and u <= -min_up:
            out.append((q, p))
    return out


def wall_evidences_of(faces: Sequence[Ellipse], intrinsics: CameraIntrinsics,
                      image: NDArray[np.uint8],
                      colour_of: Callable[[Ellipse], NDArray[np.float64]] | None = None,
                      cache: BandCache | None = None,
                      belt: NDArray[np.float64] | None = None,
                      params: PoseParams = DEFAULT_POSE) -> list[list[WallEvidence]]:
    """Per face, :func:`~stackpick_sim.vision.wall.wall_evidences` of its two unit-radius
    pose solutions (the same values; its colour :func:`~stackpick_sim.vision.wall.
    face_colour` in the (H, W, 3) RGB or (H, W) gray ``image``), every face in one array
    pass, read from the cover test's bands (:func:`~stackpick_sim.vision.wall_cover.
    face_bands`, from its ``cache``: ``params.wall_depths`` are their first depths, depth by
    depth, whatever depths the cover test adds). ``colour_of``: a face's colour, when the
    caller keeps them; ``belt``: the bare belt's colour (C,) or None; ``params``: the band's
    and the band test's settings."""
    pu, pv, keep = face_bands(faces, intrinsics, cache, pose=params)
    per = len(params.wall_depths) * WALL_RIM_POINTS
    colour = (lambda f: face_colour(f, image)) if colour_of is None else colour_of
    colours = np.array([np.asarray(colour(f), np.float64).reshape(-1) for f in faces
                        for _ in range(2)])
    tans = [tan_tilt(s.normal_cam, s.centre_cam) for f in faces
            for s in unit_circle_poses(f, intrinsics)]
    evidence = band_evidences(pu[:, :per], pv[:, :per], keep[:, :per], image, colours, tans,
                              belt, params)
    return [evidence[2 * i:2 * i + 2] for i in range(len(faces))]
