"""A face's object kind from its size, when colour cannot tell the kinds apart.

The top rule's depth test and its rest test over every kind read each face's radius: with
kinds of distinct colours it is read from the face's colour
(:func:`~stackpick_sim.vision.detector.radius_by_colour`). With kinds of one colour (the
failure class *kinds that colour cannot tell apart*, e.g. both kinds grey like the belt) the
ellipse still fixes the face's depth per metre of radius, and the detector's depth range (the
depths between the highest face a pile may show and the belt) admits only some of the kinds'
radii: a face imaged small enough that the larger kind's radius would put it beyond the belt
is of the smaller kind, one imaged large enough that the smaller kind's would put it above
the highest face is of the larger. A face both kinds' radii place within the range has no
known radius, nor has one that none does (an ellipse off every true face's size, e.g. an arc
pair, or a lower face beyond the narrower range a tracked view expects).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.vision.pose import unit_circle_poses


def depth_per_metre(ellipse: Ellipse, intrinsics: CameraIntrinsics) -> float:
    """The face centre's depth (m) per metre of its radius: the mean of the two circle
    solutions' (:func:`~stackpick_sim.vision.pose.unit_circle_poses`), as the top rule's depth
    test reads it."""
    unit = unit_circle_poses(ellipse, intrinsics)
    return 0.5 * (abs(float(unit[0].centre_cam[2])) + abs(float(unit[1].centre_cam[2])))


def size_kinds(per_metre: float, radii: Sequence[float],
               depth_range_m: tuple[float, float]) -> tuple[float, ...]:
    """The radii of ``radii`` (m) whose depth ``per_metre * r`` lies within ``depth_range_m``
    (min, max m), in their order; all of them when none does (a fit off every face's size,
    or a face outside the range a tracked view expects: its kind is unknown)."""
    near, far = depth_range_m
    inside = tuple(float(r) for r in radii if near <= per_metre * r <= far)
    return inside or tuple(float(r) for r in radii)


def kinds_by_size(intrinsics: CameraIntrinsics, radii: Sequence[float],
                  depth_range_m: tuple[float, float]
                  ) -> Callable[[Ellipse], tuple[float, ...]]:
    """Ellipse (in ``intrinsics``' pixel frame) -> the radii (m) of the kinds its size admits
    (:func:`size_kinds`); each ellipse's once."""
    known: dict[Ellipse, tuple[float, ...]] = {}

    def kinds_of(ellipse: Ellipse) -> tuple[float, ...]:
        if ellipse not in known:
            known[ellipse] = size_kinds(depth_per_metre(ellipse, intrinsics), radii,
                                        depth_range_m)
        return known[ellipse]

    return kinds_of


def one_kind(kinds_of: Callable[[Ellipse], tuple[float, ...]]
             ) -> Callable[[Ellipse], float | None]:
    """Ellipse -> the radius (m) of the one kind ``kinds_of`` admits, None when it admits
    several (with a single kind, that kind's)."""

    def radius_of(ellipse: Ellipse) -> float | None:
        kinds = kinds_of(ellipse)
        return kinds[0] if len(kinds) == 1 else None

    return radius_of


def depth_radius(radius_of: Callable[[Ellipse], float | None] | None,
                 kinds_of: Callable[[Ellipse], tuple[float, ...]] | None
                 ) -> Callable[[Ellipse], float | None] | None:
    """Ellipse -> the radius (m) the depth tests read: ``radius_of``'s (from colour), else
    the one kind ``kinds_of`` admits (:func:`one_kind`); None without either."""
    if radius_of is not None or kinds_of is None:
        return radius_of
    return one_kind(kinds_of)
