"""The methods the benchmark compares, each as ``run(frame) -> MethodOutput``.

* ``ours``: :class:`~stackpick_sim.vision.detector.TopObjectDetector` end to end.
* ``rht``, ``findellipses``, ``edgedrawing``: a baseline ellipse detector, then the same top
  rule (:func:`~stackpick_sim.vision.occlusion.select_top` over our edge map, with the
  intrinsics, the test for markings inside a face and, when the frame knows the object kinds,
  radii read from the faces' colours, as ours) and the same pose solver as ours, so
  differences in success and pose come from the ellipses (and ours' refits) alone. Their
  total time includes that edge map, the top rule and the pose; ``detector_ms`` is the
  baseline's own call.

Inputs (BGR or gray conversion) are built before the clock starts; only detector calls are
timed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from stackpick_sim.config.scene_config import VisionCfg
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.vision.baselines import (
    EdgeDrawingDetector,
    EllipseDetector,
    FindEllipsesDetector,
    RHTDetector,
)
from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.scoring import MethodOutput
from stackpick_sim.vision.detector import (
    DEFAULT_RADII_M,
    DEFAULT_TOP,
    DetectorConfig,
    TopObjectDetector,
    marking_test,
    object_kinds,
    radius_by_colour,
)
from stackpick_sim.vision.edges import edge_image
from stackpick_sim.vision.occlusion import select_top
from stackpick_sim.vision.pose import estimate_pose
from stackpick_sim.vision.roi import find_roi

#: Method names accepted by ``--methods``, in table order.
METHOD_NAMES: tuple[str, ...] = ("ours", "rht", "findellipses", "edgedrawing")


@dataclass(frozen=True)
class Method:
    """A named method: ``run`` maps a frame to its output."""

    name: str
    run: Callable[[BenchFrame], MethodOutput]


def detector_config(frame: BenchFrame, vision: VisionCfg | None = None) -> DetectorConfig:
    """What a caller knows of ``frame``: its intrinsics, depth range and object kinds (radii,
    colours and heights; the default radii when the kinds are unknown), and the settings of
    a scene's ``vision`` table (default: the defaults)."""
    least = (DEFAULT_TOP if vision is None else vision.top).kind_min_chroma_distance
    radii, colours, heights = (object_kinds(frame.kinds, least) if frame.kinds
                               else (DEFAULT_RADII_M, None, None))
    config = DetectorConfig(intrinsics=frame.intrinsics, depth_range_m=frame.depth_range_m,
                            radii_m=radii, kind_colours=colours, heights_m=heights)
    return config if vision is None else config.with_vision(vision)


def run_ours(frame: BenchFrame, vision: VisionCfg | None = None) -> MethodOutput:
    """Our detector on one frame, configured by :func:`detector_config`."""
    det = TopObjectDetector(detector_config(frame, vision))
    image = frame.image_rgb
    t0 = time.perf_counter()
    result = det.detect(image)
    total = (time.perf_counter() - t0) * 1e3
    pose = None if result.pose is None else (result.pose.x, result.pose.y,
                                             result.pose.theta_x_deg, result.pose.theta_y_deg)
    stages = {k: v for k, v in result.timings_ms.items() if k != "total"}
    return MethodOutput(ellipses=tuple(d.ellipse for d in result.ellipses),
                        top=result.top_ellipse, pose=pose, total_ms=total, detector_ms=total,
                        stages_ms=stages)


def baseline_runner(detector: EllipseDetector, vision: VisionCfg | None = None
                    ) -> Callable[[BenchFrame], MethodOutput]:
    """``run(frame)`` for a baseline detector followed by our top rule and pose solver (with
    the settings of :func:`detector_config`)."""

    def run(frame: BenchFrame) -> MethodOutput:
        bgr = np.ascontiguousarray(frame.image_rgb[:, :, ::-1])
        rgb = frame.image_rgb
        cfg = detector_config(frame, vision)
        # The bare belt's colour, an input of the top rule's wall tests: our detector reads it
        # in its roi stage (timed); the peers get it untimed, in their favour.
        belt_colour = find_roi(rgb, cfg.roi).belt
        belt = None if belt_colour is None else np.array(belt_colour)
        t0 = time.perf_counter()
        found = detector(bgr)
        t1 = time.perf_counter()
        ellipses = tuple(s.ellipse for s in found)
        grad = edge_image(rgb, cfg.edges)
        radii = cfg.radii_m
        radius_of = (None if cfg.kind_colours is None
                     else radius_by_colour(rgb, radii, cfg.kind_colours))
        choice = select_top(ellipses, grad, frame.intrinsics, radius_of, image=rgb,
                            height_of=cfg.height_of(), belt=belt,
                            markings=marking_test(cfg, rgb, grad), params=cfg.top,
                            pose_params=cfg.pose)
        pose = None
        top = None
        if choice.index is not None:
            top = ellipses[choice.index]
            radius = None if radius_of is None else radius_of(top)
            p = estimate_pose(top, frame.intrinsics, radii if radius is None else (radius,),
                              None, frame.depth_range_m, image=rgb, belt=belt,
                              params=cfg.pose)
            pose = (p.x, p.y, p.theta_x_deg, p.theta_y_deg)
        t2 = time.perf_counter()
        return MethodOutput(ellipses=ellipses, top=top, pose=pose, total_ms=(t2 - t0) * 1e3,
                            detector_ms=(t1 - t0) * 1e3,
                            stages_ms={"detector": (t1 - t0) * 1e3, "top+pose": (t2 - t1) * 1e3})

    return run


def make_methods(names: list[str], seed: int = 0, vision: VisionCfg | None = None
                 ) -> list[Method]:
    """Methods by name (see METHOD_NAMES); ``seed`` seeds the RHT per call; ``vision``: a
    scene's ``vision`` table, the settings of ours and of the top rule and pose after the
    baselines (default: the defaults)."""
    factories: dict[str, Callable[[], Method]] = {
        "ours": lambda: Method("ours", lambda frame: run_ours(frame, vision)),
        "rht": lambda: Method("rht", baseline_runner(RHTDetector(seed=seed), vision)),
        "findellipses": lambda: Method("findellipses",
                                       baseline_runner(FindEllipsesDetector(), vision)),
        "edgedrawing": lambda: Method("edgedrawing",
                                      baseline_runner(EdgeDrawingDetector(), vision)),
    }
    unknown = [n for n in names if n not in factories]
    if unknown:
        raise ConfigError(f"unknown method(s) {', '.join(unknown)}; known: "
                          f"{', '.join(METHOD_NAMES)}")
    return [factories[n]() for n in names]
