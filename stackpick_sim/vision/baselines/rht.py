"""The paper's baseline: Randomized Hough Transform ellipse detection (Xu/Oja-style RHT).

Section 2.2 of the paper: three edge points give the three parameters (A, H, B) of
``A x^2 + 2 H x y + B y^2 = 1`` (Eq. 1) about the ellipse centre, a valid ellipse has
``A B - H^2 > 0`` (Eq. 2), and the centre comes from the three points' tangents (Fig. 5).

Per frame:

1. Edges as in the paper's section 2.1: Gaussian, Sobel magnitude threshold, thinning
   (``cv2.ximgproc.thinning``, Zhang-Suen). Each edge pixel keeps its Sobel gradient; the
   tangent is perpendicular to it.
2. Sample batches of point triples (vectorised). For each pair (P1, P2) the tangents meet at
   T and the chord's midpoint is M; the centre lies on line TM (Fig. 5). Two pairs give two
   such lines and their intersection is the centre. Homogeneous coordinates handle parallel
   tangents (T at infinity) without a special case.
3. Solve Eq. 1 about that centre for (A, H, B), keep Eq. 2 solutions of plausible size whose
   normals agree with the three pixels' gradients, and vote in a hashed accumulator over
   coarse (cx, cy, a, b, angle) bins. Each bin also sums (cx, cy, A, H, B), so the candidate
   of a bin is the mean of its votes.
4. When a bin reaches the vote threshold, verify its candidate against the remaining edge
   pixels: the share of the outline covered by edge pixels near it with agreeing gradients.
   Accepted candidates are refined by a direct least-squares fit to those pixels, kept, their
   pixels removed and the accumulator cleared (Xu's RHT); rejected bins are dropped.
5. Stop when the triple budget is spent, too few edge pixels remain, or many batches pass
   without a detection.

Outputs are reproducible: the same seed (or equally seeded Generator) and image give the same
detections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ConfigError
from stackpick_sim.geometry import Ellipse
from stackpick_sim.vision.baselines.common import (
    ScoredEllipse,
    as_gray,
    sort_by_score,
    too_small,
)
from stackpick_sim.vision.baselines.edges import (
    GAUSSIAN_SIGMA_PX,
    SOBEL_MAGNITUDE_THRESHOLD,
    EdgePixels,
    EdgeSource,
    extract_edges,
)
from stackpick_sim.vision.baselines.rht_voting import (
    Accumulator,
    bin_keys,
    conic_axes,
    solve_ahb,
    triple_centres,
)

FloatArray = NDArray[np.float64]

# --- sampling -----------------------------------------------------------------------------
#: Object size range, semi-axes in px. The benchmark draws 15-45 px; the margin admits fit
#: error. Bounds both the votes and the sampling window.
MIN_SEMI_AXIS_PX = 8.0
MAX_SEMI_AXIS_PX = 60.0
#: Thinnest ellipse accepted (b / a). 0.2 is a face tilted ~78 deg, beyond any pickable pose.
MIN_AXIS_RATIO = 0.2
#: Points of a triple closer than this give ill-conditioned tangent intersections.
MIN_PAIR_DISTANCE_PX = 6.0
#: Triples per vectorised batch: large enough to amortise numpy overhead, small enough that
#: detections (and the pixel removal that follows) happen between batches.
BATCH_SIZE = 4096
#: Triple budget per frame (Xu's "sample budget").
MAX_TRIPLES = 400_000
#: Stop after this many consecutive batches without an accepted ellipse.
MAX_IDLE_BATCHES = 30
#: Stop when fewer edge pixels than this remain: the smallest ellipse's outline is ~60 px.
MIN_EDGE_PIXELS = 30
#: A triple's three gradients must agree with the fitted ellipse's normals to within this.
#: It rejects most triples drawn from different objects before they vote.
NORMAL_TOLERANCE_DEG = 20.0

# --- accumulator (bin widths: rht_voting) -------------------------------------------------
#: Votes that make a bin a candidate (Xu's threshold). With the bins of rht_voting, three
#: coincident triples from different objects are rare.
VOTE_THRESHOLD = 3

# --- verification -------------------------------------------------------------------------
#: Candidates verified per batch, most-voted first; the rest wait in the accumulator. In
#: dense stacks hundreds of bins reach the threshold at once, nearly all false.
MAX_VERIFY_PER_BATCH = 8
#: Edge pixels within this (Sampson) distance of the candidate, px, support it.
SUPPORT_TOLERANCE_PX = 1.5
#: Pixels within this distance of an accepted ellipse are removed from the pool.
REMOVAL_TOLERANCE_PX = 2.5
#: The outline is cut into arcs of this length, px; coverage is the share of arcs holding a
#: supporting pixel.
COVERAGE_ARC_PX = 2.0
#: Accept a candidate when at least this share of its outline is supported. Ellipses under
#: others show 40-70 % of their outline; arcs chained across two objects rarely reach this.
MIN_COVERAGE = 0.45


@dataclass(frozen=True, kw_only=True)
class RHTConfig:
    """Tunable constants of :func:`detect_ellipses_rht` (defaults: module constants)."""

    #: "paper": Gaussian + Sobel + thinning (section 2.1); "shared": the package's edge stage.
    edge_source: EdgeSource = "paper"
    gaussian_sigma_px: float = GAUSSIAN_SIGMA_PX
    sobel_magnitude_threshold: float = SOBEL_MAGNITUDE_THRESHOLD
    min_semi_axis_px: float = MIN_SEMI_AXIS_PX
    max_semi_axis_px: float = MAX_SEMI_AXIS_PX
    min_axis_ratio: float = MIN_AXIS_RATIO
    batch_size: int = BATCH_SIZE
    max_triples: int = MAX_TRIPLES
    max_idle_batches: int = MAX_IDLE_BATCHES
    vote_threshold: int = VOTE_THRESHOLD
    min_coverage: float = MIN_COVERAGE
    refine: bool = True

    def __post_init__(self) -> None:
        if not 0.0 < self.min_semi_axis_px < self.max_semi_axis_px:
            raise ConfigError(
                f"semi-axis range ({self.min_semi_axis_px}, {self.max_semi_axis_px}) px invalid;"
                " need 0 < min < max")
        if self.gaussian_sigma_px <= 0.0 or self.sobel_magnitude_threshold <= 0.0:
            raise ConfigError("gaussian_sigma_px and sobel_magnitude_threshold must be > 0, got "
                              f"{self.gaussian_sigma_px}, {self.sobel_magnitude_threshold}")
        if self.batch_size < 1 or self.max_triples < 1 or self.max_idle_batches < 1:
            raise ConfigError("batch_size, max_triples and max_idle_batches must be >= 1")
        if self.edge_source not in ("paper", "shared"):
            raise ConfigError(f"unknown edge_source {self.edge_source!r}; known: paper, shared")
        if self.vote_threshold < 1:
            raise ConfigError(f"vote_threshold {self.vote_threshold} must be >= 1")
        if not 0.0 < self.min_coverage <= 1.0 or not 0.0 < self.min_axis_ratio <= 1.0:
            raise ConfigError("min_coverage and min_axis_ratio must lie in (0, 1]")

def _ellipse_from_params(cx: float, cy: float, ahb: FloatArray) -> Ellipse | None:
    """Ellipse of centre (cx, cy) px and Eq. 1 parameters (A, H, B); None if Eq. 2 fails."""
    a_, h_, b_ = (float(v) for v in ahb)
    if not (a_ > 0.0 and a_ * b_ - h_ * h_ > 0.0):
        return None
    sa, sb, ang = conic_axes(np.array([[a_, h_, b_]]))
    return Ellipse(cx=cx, cy=cy, a=float(sa[0]), b=float(sb[0]), angle_deg=float(ang[0]))


def _support(e: Ellipse, edges: EdgePixels, alive: NDArray[np.bool_], tol_px: float,
             check_normals: bool) -> tuple[NDArray[np.bool_], float]:
    """Alive edge pixels supporting ``e`` ((N,) mask) and the outline coverage in [0, 1].

    Support: Sampson distance to the conic <= ``tol_px`` and, with ``check_normals``, the
    pixel's gradient within NORMAL_TOLERANCE_DEG of the ellipse normal.
    """
    u0, v0, u1, v1 = e.bounds()
    p_all = edges.points
    idx = np.flatnonzero(alive & (p_all[:, 0] >= u0 - tol_px) & (p_all[:, 0] <= u1 + tol_px)
                         & (p_all[:, 1] >= v0 - tol_px) & (p_all[:, 1] <= v1 + tol_px))
    conic = e.conic()
    m, d, f = conic[:2, :2], conic[:2, 2], conic[2, 2]
    p = p_all[idx]
    q = np.einsum("ni,ij,nj->n", p, m, p) + 2.0 * p @ d + f
    grad = 2.0 * (p @ m + d)
    gnorm = np.maximum(np.linalg.norm(grad, axis=1), 1e-12)
    ok = np.abs(q) / gnorm <= tol_px
    if check_normals:
        cos = np.abs(np.einsum("ni,ni->n", grad, edges.gradients[idx])) / gnorm
        ok &= cos >= math.cos(math.radians(NORMAL_TOLERANCE_DEG))
    near = np.zeros(len(p_all), dtype=bool)
    near[idx[ok]] = True
    if not ok.any():
        return near, 0.0
    th = math.radians(e.angle_deg)
    rel = p[ok] - (e.cx, e.cy)
    xr = rel[:, 0] * math.cos(th) + rel[:, 1] * math.sin(th)
    yr = -rel[:, 0] * math.sin(th) + rel[:, 1] * math.cos(th)
    phase = np.arctan2(yr / e.b, xr / e.a)
    perimeter = math.pi * (3 * (e.a + e.b) - math.sqrt((3 * e.a + e.b) * (e.a + 3 * e.b)))
    n_arcs = max(8, math.ceil(perimeter / COVERAGE_ARC_PX))
    arcs = np.floor((phase + math.pi) / (2 * math.pi) * n_arcs).astype(np.int64) % n_arcs
    return near, float(len(np.unique(arcs))) / n_arcs


def _refit(e: Ellipse, edges: EdgePixels, mask: NDArray[np.bool_]) -> Ellipse | None:
    """Direct least-squares ellipse through the (N,) masked edge pixels; None if it fails."""
    pts = edges.points[mask].astype(np.float32)
    if len(pts) < 6:
        return None
    (cx, cy), (w, h), ang = cv2.fitEllipseDirect(pts)
    a, b, angle = 0.5 * w, 0.5 * h, ang
    if a < b:
        a, b, angle = b, a, angle + 90.0
    vals = (cx, cy, a, b, angle)
    if not all(math.isfinite(v) for v in vals) or b <= 0.0:
        return None
    return Ellipse(cx=float(cx), cy=float(cy), a=float(a), b=float(b),
                   angle_deg=float(angle) % 180.0)


def _plausible(e: Ellipse, cfg: RHTConfig) -> bool:
    return (cfg.min_semi_axis_px <= e.b and e.a <= cfg.max_semi_axis_px
            and e.b / e.a >= cfg.min_axis_ratio)


def _vote_batch(edges: EdgePixels, alive_idx: NDArray[np.int64], rng: np.random.Generator,
                cfg: RHTConfig, shape: tuple[int, int]) -> tuple[NDArray[np.int64], FloatArray]:
    """Sample ``cfg.batch_size`` triples; return bin keys (K,) and (K, 5) votes of valid ones."""
    tri = alive_idx[rng.integers(0, len(alive_idx), size=(cfg.batch_size, 3))]
    p, t = edges.points[tri], edges.tangents[tri]
    d = np.linalg.norm(p[:, [0, 1, 2]] - p[:, [1, 2, 0]], axis=2)
    keep = np.all((d >= MIN_PAIR_DISTANCE_PX) & (d <= 2.0 * cfg.max_semi_axis_px), axis=1)
    p, t = p[keep], t[keep]
    centre, ok = triple_centres(p, t)
    h, w = shape
    margin = cfg.max_semi_axis_px
    with np.errstate(invalid="ignore"):
        ok &= ((centre[:, 0] > -margin) & (centre[:, 0] < w + margin)
               & (centre[:, 1] > -margin) & (centre[:, 1] < h + margin))
    p, t, centre = p[ok], t[ok], centre[ok]
    x = p - centre[:, None, :]
    r = np.linalg.norm(x, axis=2)
    ok = np.all((r >= cfg.min_semi_axis_px) & (r <= cfg.max_semi_axis_px), axis=1)
    ahb, solvable = solve_ahb(x[ok])
    p, t, centre, x = p[ok][solvable], t[ok][solvable], centre[ok][solvable], x[ok][solvable]
    ahb = ahb[solvable]
    # Eq. 2 (with A > 0: the form must be positive definite to equal +1 on a real ellipse).
    ok = (ahb[:, 0] > 0.0) & (ahb[:, 0] * ahb[:, 2] - ahb[:, 1] ** 2 > 0.0)
    ahb, t, centre, x = ahb[ok], t[ok], centre[ok], x[ok]
    sa, sb, ang = conic_axes(ahb)
    ok = (sb >= cfg.min_semi_axis_px) & (sa <= cfg.max_semi_axis_px)
    ok &= sb / sa >= cfg.min_axis_ratio
    # The conic's normal M x at each point must be perpendicular to that pixel's tangent.
    mx = np.stack([ahb[:, None, 0] * x[..., 0] + ahb[:, None, 1] * x[..., 1],
                   ahb[:, None, 1] * x[..., 0] + ahb[:, None, 2] * x[..., 1]], axis=-1)
    sin_err = np.abs(np.sum(mx * t, axis=-1)) / np.linalg.norm(mx, axis=-1)
    ok &= np.all(sin_err <= math.sin(math.radians(NORMAL_TOLERANCE_DEG)), axis=1)
    keys = bin_keys(centre[ok, 0], centre[ok, 1], sa[ok], sb[ok], ang[ok])
    return keys, np.concatenate([centre[ok], ahb[ok]], axis=1)


def detect_ellipses_rht(image: NDArray[np.uint8],
                        rng: np.random.Generator | int,
                        config: RHTConfig | None = None) -> list[ScoredEllipse]:
    """Detect ellipses in an (H, W) gray or (H, W, 3) BGR uint8 image with RHT.

    ``rng``: a Generator (advanced by the call) or an int seed. Score: the share of the
    outline supported by edge pixels, in [0, 1]. Sorted by descending score; [] when nothing
    is found. Raises ImageError only for arrays that are not images.
    """
    cfg = config or RHTConfig()
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    gray = as_gray(image)
    if too_small(gray):
        return []
    edges = extract_edges(gray, sigma_px=cfg.gaussian_sigma_px,
                          threshold=cfg.sobel_magnitude_threshold, source=cfg.edge_source)
    alive = np.ones(len(edges.points), dtype=bool)
    acc = Accumulator.empty()
    found: list[ScoredEllipse] = []
    triples, idle = 0, 0
    while triples < cfg.max_triples and idle < cfg.max_idle_batches:
        alive_idx = np.flatnonzero(alive)
        if len(alive_idx) < MIN_EDGE_PIXELS:
            break
        keys, params = _vote_batch(edges, alive_idx, gen, cfg, gray.shape)
        triples += cfg.batch_size
        idle += 1
        if len(keys) == 0:
            continue
        acc.add(keys, params)
        cands = np.flatnonzero(acc.counts >= cfg.vote_threshold)
        # Most-voted first; ties by key (np.unique sorted them) keep the order deterministic.
        cands = cands[np.argsort(-acc.counts[cands], kind="stable")][:MAX_VERIFY_PER_BATCH]
        for ci in cands:
            mean = acc.sums[ci] / acc.counts[ci]
            e = _ellipse_from_params(float(mean[0]), float(mean[1]), mean[2:])
            if e is not None and _accept(e, edges, alive, cfg, found):
                acc = Accumulator.empty()  # Xu: the pixel set changed, restart voting
                idle = 0
                break
        else:
            acc.drop(cands)  # every candidate failed verification
    return sort_by_score(found)


def _accept(e: Ellipse, edges: EdgePixels, alive: NDArray[np.bool_], cfg: RHTConfig,
            found: list[ScoredEllipse]) -> bool:
    """Verify candidate ``e``; on success append it to ``found`` and clear its pixels."""
    if not _plausible(e, cfg):
        return False
    support, coverage = _support(e, edges, alive, SUPPORT_TOLERANCE_PX, check_normals=True)
    if coverage < cfg.min_coverage:
        return False
    if cfg.refine:
        refined = _refit(e, edges, support)
        if refined is not None and _plausible(refined, cfg):
            _, r_coverage = _support(refined, edges, alive, SUPPORT_TOLERANCE_PX,
                                     check_normals=True)
            if r_coverage >= coverage:
                e, coverage = refined, r_coverage
    remove, _ = _support(e, edges, alive, REMOVAL_TOLERANCE_PX, check_normals=False)
    alive &= ~remove
    found.append(ScoredEllipse(ellipse=e, score=min(1.0, coverage)))
    return True


@dataclass(frozen=True, kw_only=True)
class RHTDetector:
    """:func:`detect_ellipses_rht` behind the common interface, reseeded on every call.

    A fresh ``np.random.default_rng(seed)`` per call makes each call a pure function of the
    image, so repeated or reordered calls give identical detections.
    """

    seed: int = 0
    config: RHTConfig = field(default_factory=RHTConfig)
    name: str = "RHT"

    def __call__(self, image: NDArray[np.uint8]) -> list[ScoredEllipse]:
        """Detect ellipses in an (H, W) gray or (H, W, 3) BGR uint8 image."""
        return detect_ellipses_rht(image, np.random.default_rng(self.seed), self.config)
