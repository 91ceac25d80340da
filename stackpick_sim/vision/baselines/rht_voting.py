"""RHT's vectorised kernels: the three-point ellipse (Fig. 5, Eq. 1-2) and the accumulator.

All functions work on K samples at once; pixel coordinates (u, v), px.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Bin widths: centre and semi-axes 3 px (the scatter of three-point solutions on 1 px
#: digitised edges is about this), angle 10 deg (the angle of a nearly round ellipse is
#: ill-defined, so it is binned only when b / a < ROUND_AXIS_RATIO).
CENTRE_BIN_PX = 3.0
AXIS_BIN_PX = 3.0
ANGLE_BIN_DEG = 10.0
ROUND_AXIS_RATIO = 0.9


def homog(p: FloatArray) -> FloatArray:
    """(..., 2) points to (..., 3) homogeneous."""
    return np.concatenate([p, np.ones((*p.shape[:-1], 1))], axis=-1)


def triple_centres(p: FloatArray, t: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Centres of (K, 3, 2) point triples with (K, 3, 2) tangents; (K, 2) and a (K,) valid mask.

    For the pairs (0, 1) and (1, 2): the tangent lines meet at T, the chord midpoint is M and
    the centre lies on line MT (Fig. 5 of the paper); the two lines meet at the centre.
    """
    ph = homog(p)
    lines = np.cross(ph, ph + np.concatenate([t, np.zeros((*t.shape[:-1], 1))], axis=-1))
    centre_lines = []
    for i, j in ((0, 1), (1, 2)):
        tij = np.cross(lines[:, i], lines[:, j])
        mij = homog(0.5 * (p[:, i] + p[:, j]))
        centre_lines.append(np.cross(mij, tij))
    c = np.cross(centre_lines[0], centre_lines[1])
    norm = np.linalg.norm(c[:, :2], axis=1)
    ok = np.abs(c[:, 2]) > 1e-9 * np.maximum(norm, 1e-300)
    out = np.full((len(p), 2), np.nan)
    out[ok] = c[ok, :2] / c[ok, 2:3]
    return out, ok


def solve_ahb(x: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Eq. 1 through (K, 3, 2) centred points: (K, 3) (A, H, B) and a (K,) solvable mask."""
    m = np.stack([x[..., 0] ** 2, 2.0 * x[..., 0] * x[..., 1], x[..., 1] ** 2], axis=-1)
    scale = np.max(np.abs(m), axis=(1, 2))
    det = np.linalg.det(m)
    ok = np.abs(det) > 1e-6 * np.maximum(scale, 1e-300) ** 3
    ahb = np.full((len(x), 3), np.nan)
    if ok.any():
        ahb[ok] = np.linalg.solve(m[ok], np.ones((int(ok.sum()), 3, 1)))[..., 0]
    return ahb, ok


def conic_axes(ahb: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Semi-axes a >= b (px) and major-axis angle (deg, [0, 180)) of (K, 3) (A, H, B), AB>H^2."""
    a_, h_, b_ = ahb[:, 0], ahb[:, 1], ahb[:, 2]
    mean = 0.5 * (a_ + b_)
    root = np.hypot(0.5 * (a_ - b_), h_)
    lam_small, lam_big = mean - root, mean + root
    with np.errstate(divide="ignore", invalid="ignore"):  # callers drop non-ellipses after
        semi_a = 1.0 / np.sqrt(lam_small)
        semi_b = 1.0 / np.sqrt(lam_big)
    # 0.5 atan2(2H, A - B) points along the big-eigenvalue (minor) axis; the major is 90 deg on.
    angle = (np.degrees(0.5 * np.arctan2(2.0 * h_, a_ - b_)) + 90.0) % 180.0
    return semi_a, semi_b, angle


@dataclass
class Accumulator:
    """Hashed accumulator: sorted int64 bin keys, vote counts and per-bin parameter sums."""

    keys: NDArray[np.int64]
    counts: NDArray[np.int64]
    sums: FloatArray  # (K, 5): cx, cy, A, H, B

    @classmethod
    def empty(cls) -> Accumulator:
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 5)))

    def add(self, keys: NDArray[np.int64], params: FloatArray) -> None:
        """Add one vote per key with its (len(keys), 5) parameters."""
        all_keys = np.concatenate([self.keys, keys])
        uniq, inv = np.unique(all_keys, return_inverse=True)
        weights = np.concatenate([self.counts, np.ones(len(keys), np.int64)])
        self.counts = np.bincount(inv, weights=weights, minlength=len(uniq)).astype(np.int64)
        values = np.concatenate([self.sums, params])
        self.sums = np.stack([np.bincount(inv, weights=values[:, k], minlength=len(uniq))
                              for k in range(5)], axis=1)
        self.keys = uniq

    def drop(self, index: NDArray[np.int64]) -> None:
        """Delete the bins at ``index`` (rejected candidates never come back as such)."""
        keep = np.ones(len(self.keys), dtype=bool)
        keep[index] = False
        self.keys, self.counts, self.sums = self.keys[keep], self.counts[keep], self.sums[keep]


def bin_keys(cx: FloatArray, cy: FloatArray, a: FloatArray, b: FloatArray,
              angle: FloatArray) -> NDArray[np.int64]:
    """Pack quantised (cx, cy, a, b, angle) into (K,) int64 keys; 10 bits per field."""
    ix = np.rint(cx / CENTRE_BIN_PX).astype(np.int64) + 64  # +64: centres slightly off-image
    iy = np.rint(cy / CENTRE_BIN_PX).astype(np.int64) + 64
    ia = np.rint(a / AXIS_BIN_PX).astype(np.int64)
    ib = np.rint(b / AXIS_BIN_PX).astype(np.int64)
    n_angle = round(180.0 / ANGLE_BIN_DEG)
    it = np.rint(angle / ANGLE_BIN_DEG).astype(np.int64) % n_angle + 1
    it = np.where(b / a >= ROUND_AXIS_RATIO, 0, it)
    return ((((ix * 1024 + iy) * 1024 + ia) * 1024 + ib) * 64 + it).astype(np.int64)
