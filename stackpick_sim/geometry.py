"""Camera and ellipse geometry shared by ground truth, vision and control.

Conventions (everyone in the package uses these, nowhere else are they restated):

* **Camera frame** is OpenCV's: x right, y down, z forward along the optical axis, metres.
  MuJoCo cameras look along their -z with y up; ``MJ_CAM_TO_CV`` converts
  (``R_world_cv = R_world_mjcam @ MJ_CAM_TO_CV``).
* **Pixels**: (u, v) = (column, row), floats, row 0 at the top; integer values are pixel
  *centres* (OpenCV's convention), so the principal point of a centred camera is
  ((W - 1) / 2, (H - 1) / 2).
* **Ellipse**: centre (cx, cy) px, semi-axes a >= b px, ``angle_deg`` in [0, 180) the
  direction of the major axis measured from +u towards +v (clockwise on screen), exactly what
  ``cv2.ellipse(img, ((cx, cy), (2a, 2b), angle_deg), ...)`` draws.
* **Tilt angles** (the paper's theta_x, theta_y, degrees): with ``m`` the face normal pointing
  *into* the object (away from the camera for a visible face) in the camera frame,
  ``theta_x = atan2(-m_y, m_z)`` and ``theta_y = atan2(m_x, m_z)``: the rotations of the
  optical axis about camera X and Y that bring it onto ``m``. Both are 0 for a face square
  to the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ConfigError

#: Rotation taking MuJoCo camera axes (x right, y up, -z forward) to OpenCV's.
MJ_CAM_TO_CV: NDArray[np.float64] = np.diag([1.0, -1.0, -1.0])

FloatArray = NDArray[np.float64]
#: Vertical fields of view a pinhole camera model may have, degrees: from a long telephoto
#: lens (1 deg) to the widest rectilinear lenses (170 deg); a pinhole image of a wider field
#: stretches without bound towards its edges.
FOVY_RANGE_DEG = (1.0, 170.0)


def check_fovy(fovy_deg: float) -> None:
    """ConfigError unless ``fovy_deg`` is a vertical field of view in FOVY_RANGE_DEG."""
    lo, hi = FOVY_RANGE_DEG
    if not (math.isfinite(fovy_deg) and lo <= fovy_deg <= hi):
        raise ConfigError(f"vertical field of view {fovy_deg!r} deg is out of range; "
                          f"allowed: {lo:g} to {hi:g} degrees")


@dataclass(frozen=True, kw_only=True)
class CameraIntrinsics:
    """Pinhole intrinsics in pixels, with the lens's Brown-Conrady distortion.

    ``fx``, ``fy``: focal lengths, px, finite and > 0; ``cx``, ``cy``: principal point, px,
    finite; ``width``, ``height``: image size, px, >= 1. Anything else raises ConfigError.
    :meth:`project` and :meth:`normalized` are the pinhole model: they map to and from
    *undistorted* pixels (what MuJoCo renders; ground-truth ellipses are exact there).
    ``dist`` says how the camera's image is distorted from them
    (:mod:`stackpick_sim.vision.undistort` undoes it).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    """(k1, k2, p1, p2, k3), OpenCV's order; all 0: an ideal pinhole."""

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"camera intrinsics {name} = {value!r} is out of range; "
                                  "allowed: a finite focal length > 0 px")
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"camera intrinsics {name} = {getattr(self, name)!r} must "
                                  "be a finite principal point, px")
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ConfigError(f"camera intrinsics {name} = {value!r} must be an image "
                                  "size of at least 1 px")

    @classmethod
    def from_fovy(cls, fovy_deg: float, width: int, height: int,
                  dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
                  ) -> CameraIntrinsics:
        """Intrinsics of a MuJoCo camera of vertical field of view ``fovy_deg``, square pixels.

        ``fovy_deg`` must lie in FOVY_RANGE_DEG (ConfigError otherwise).
        """
        check_fovy(fovy_deg)
        f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2.0)
        return cls(fx=f, fy=f, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0,
                   width=width, height=height, dist=dist)

    @property
    def distorted(self) -> bool:
        """Whether the lens distorts (any coefficient non-zero)."""
        return any(c != 0.0 for c in self.dist)

    @property
    def K(self) -> FloatArray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points_cam: FloatArray) -> FloatArray:
        """Project (N, 3) camera-frame points (metres) to (N, 2) pixels (u, v)."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        z = p[:, 2]
        return np.stack([self.fx * p[:, 0] / z + self.cx, self.fy * p[:, 1] / z + self.cy], axis=1)

    def normalized(self, pixels: FloatArray) -> FloatArray:
        """(N, 2) pixels to (N, 2) normalised image coordinates (x/z, y/z)."""
        px = np.atleast_2d(np.asarray(pixels, dtype=float))
        return np.stack([(px[:, 0] - self.cx) / self.fx, (px[:, 1] - self.cy) / self.fy], axis=1)


@dataclass(frozen=True, kw_only=True)
class Ellipse:
    """An image ellipse; see the module docstring for the conventions."""

    cx: float
    cy: float
    a: float
    b: float
    angle_deg: float

    @classmethod
    def of(cls, cx: float, cy: float, a: float, b: float, angle_deg: float) -> Ellipse:
        """``Ellipse(cx=cx, ...)`` (an equal object) at a third of the frozen dataclass
        constructor's cost, for the detector's hot loops: the fields are written to the
        instance dict directly (Ellipse has no validation to skip)."""
        e = object.__new__(cls)
        d = e.__dict__
        d["cx"], d["cy"], d["a"], d["b"], d["angle_deg"] = cx, cy, a, b, angle_deg
        return e

    @property
    def area(self) -> float:
        """Area in px^2."""
        return math.pi * self.a * self.b

    def conic(self) -> FloatArray:
        """(3, 3) symmetric matrix C with [u, v, 1] C [u, v, 1]^T = 0 on the ellipse, < 0 inside."""
        t = math.radians(self.angle_deg)
        c, s = math.cos(t), math.sin(t)
        rot = np.array([[c, -s], [s, c]])
        m = rot @ np.diag([1.0 / self.a**2, 1.0 / self.b**2]) @ rot.T
        centre = np.array([self.cx, self.cy])
        d = -m @ centre
        f = float(centre @ m @ centre) - 1.0
        return np.array([[m[0, 0], m[0, 1], d[0]], [m[1, 0], m[1, 1], d[1]], [d[0], d[1], f]])

    @classmethod
    def from_conic(cls, conic: FloatArray) -> Ellipse:
        """The ellipse of a (3, 3) conic matrix; raises ValueError if it is not a real ellipse."""
        c = np.asarray(conic, dtype=float)
        c = 0.5 * (c + c.T)
        m = c[:2, :2]
        d = c[:2, 2]
        if np.linalg.det(m) <= 0:
            raise ValueError("conic is not an ellipse (det of its quadratic part <= 0)")
        centre = np.linalg.solve(m, -d)
        f = float(c[2, 2] + d @ centre)
        evals, evecs = np.linalg.eigh(m)
        if f * evals[0] >= 0:
            raise ValueError("conic is an imaginary or degenerate ellipse")
        axes = np.sqrt(-f / evals)  # ascending eigenvalues -> descending axes
        major = evecs[:, 0]
        angle = math.degrees(math.atan2(major[1], major[0])) % 180.0
        return cls(cx=float(centre[0]), cy=float(centre[1]), a=float(axes[0]), b=float(axes[1]),
                   angle_deg=angle)

    def points(self, n: int = 64) -> FloatArray:
        """(n, 2) pixels evenly spaced in parameter along the outline."""
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        th = math.radians(self.angle_deg)
        c, s = math.cos(th), math.sin(th)
        x, y = self.a * np.cos(t), self.b * np.sin(t)
        return np.stack([self.cx + c * x - s * y, self.cy + s * x + c * y], axis=1)

    def bounds(self) -> tuple[float, float, float, float]:
        """Axis-aligned bounding box (u_min, v_min, u_max, v_max) in px."""
        th = math.radians(self.angle_deg)
        hw = math.hypot(self.a * math.cos(th), self.b * math.sin(th))
        hh = math.hypot(self.a * math.sin(th), self.b * math.cos(th))
        return self.cx - hw, self.cy - hh, self.cx + hw, self.cy + hh

    def inside(self, points: NDArray[np.float64], margin_px: float = 0.0) -> NDArray[np.bool_]:
        """(M,) bool: points (M, 2) (u, v) more than ``margin_px`` inside the ellipse (strictly
        inside its axes shrunk by that much)."""
        t = math.radians(self.angle_deg)
        c, s = math.cos(t), math.sin(t)
        du, dv = points[:, 0] - self.cx, points[:, 1] - self.cy
        x = (c * du + s * dv) / max(self.a - margin_px, 1e-6)
        y = (-s * du + c * dv) / max(self.b - margin_px, 1e-6)
        return np.asarray(x * x + y * y < 1.0, np.bool_)

    def mask(self, shape: tuple[int, int]) -> NDArray[np.bool_]:
        """(H, W) bool mask of the pixel centres inside the ellipse."""
        h, w = shape
        out = np.zeros((h, w), dtype=bool)
        u0, v0, u1, v1 = self.bounds()
        c0, c1 = max(0, math.floor(u0)), min(w, math.ceil(u1) + 1)
        r0, r1 = max(0, math.floor(v0)), min(h, math.ceil(v1) + 1)
        if c0 >= c1 or r0 >= r1:
            return out
        uu, vv = np.meshgrid(np.arange(c0, c1, dtype=float) - self.cx,
                             np.arange(r0, r1, dtype=float) - self.cy)
        th = math.radians(self.angle_deg)
        c, s = math.cos(th), math.sin(th)
        x = c * uu + s * vv
        y = -s * uu + c * vv
        out[r0:r1, c0:c1] = (x / self.a) ** 2 + (y / self.b) ** 2 <= 1.0
        return out

    def as_dict(self) -> dict[str, float]:
        """JSON-friendly dict with keys cx, cy, a, b, angle_deg."""
        return {"cx": self.cx, "cy": self.cy, "a": self.a, "b": self.b, "angle_deg": self.angle_deg}


def mask_iou(e1: Ellipse, e2: Ellipse, shape: tuple[int, int]) -> float:
    """Pixel-mask intersection over union of two ellipses rasterised on an (H, W) image."""
    m1, m2 = e1.mask(shape), e2.mask(shape)
    union = np.count_nonzero(m1 | m2)
    return float(np.count_nonzero(m1 & m2)) / union if union else 0.0


def plane_basis(normal: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors (u, v) completing the unit ``normal`` to a right-handed basis."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def project_circle(centre_cam: FloatArray, normal_cam: FloatArray, radius: float,
                   intrinsics: CameraIntrinsics) -> Ellipse:
    """Exact perspective image of a 3-D circle.

    ``centre_cam`` (3,) metres and ``normal_cam`` (3,) in the camera frame, ``radius`` metres.
    The image of a circle under a pinhole is the conic ``H^-T diag(1, 1, -r^2) H^-1`` with
    ``H = K [u v c]`` the plane-to-image homography. Raises ValueError when part of the circle
    is behind the camera (its image is then not an ellipse).
    """
    c = np.asarray(centre_cam, dtype=float)
    u, v = plane_basis(normal_cam)
    n = np.cross(u, v)
    if c[2] - radius * math.sqrt(max(0.0, 1.0 - n[2] ** 2)) <= 1e-9:
        raise ValueError("circle reaches behind the camera")
    h = intrinsics.K @ np.column_stack([u, v, c])
    h_inv = np.linalg.inv(h)
    conic = h_inv.T @ np.diag([1.0, 1.0, -radius**2]) @ h_inv
    return Ellipse.from_conic(conic)


def tilt_angles(inward_normal_cam: FloatArray) -> tuple[float, float]:
    """(theta_x, theta_y) degrees of a face from its normal *into* the object (camera frame)."""
    m = np.asarray(inward_normal_cam, dtype=float)
    return (math.degrees(math.atan2(-m[1], m[2])), math.degrees(math.atan2(m[0], m[2])))


def normal_from_tilt(theta_x_deg: float, theta_y_deg: float) -> FloatArray:
    """Unit inward face normal (camera frame) with the given tilt angles; inverse of tilt_angles."""
    m = np.array([math.tan(math.radians(theta_y_deg)), -math.tan(math.radians(theta_x_deg)), 1.0])
    return m / np.linalg.norm(m)


def face_depth_range(camera_height: float, max_face_height: float) -> tuple[float, float]:
    """(min, max) depth, m, at which a top face can lie for a camera looking straight down
    from ``camera_height`` m above the belt: from ``max_face_height`` above the belt (the
    scene's ``objects.max_face_height``: the generator redraws taller piles) down to the belt
    itself. What the detectors may assume of a face's distance."""
    return (max(1e-3, camera_height - max_face_height), max(2e-3, camera_height))
