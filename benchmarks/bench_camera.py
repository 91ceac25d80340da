"""Cost of the camera model per frame against the paper scene's, and the motion-blur error.

    python benchmarks/bench_camera.py [--seed 20000] [--frames 40]

Writes benchmarks/results/camera.md and camera.json:

- **Frame cost**: CPU ms per wrist-camera frame (render, exposure, lens, sensor; what an episode
  pays per frame) of the paper scene, of ``realistic``, and of the paper scene with one
  realism feature switched on at a time, all measured in this one run on the same seed,
  taking frames in turns; the ratio is to the paper scene's frame.
- **Where the realistic frame's time goes**: CPU ms per frame of each stage (MuJoCo's
  render, the blur's smear and its image motion, the lens remap, vignetting, the sensor's
  noise, quantisation).
- **Shadow map size**: the mean grey-level difference of a frame with a 256 or 512 px map
  from one with a 1024 px map, on the pixels the shadows change (more than 5 grey levels
  between shadows on and off).
- **Motion blur**: on a pile moving with the belt (every object given the belt's velocity;
  the belt's textured skin moves with it), the mean and 99th-percentile grey-level error of
  no blur, of ``blur = "subframes"`` with n renders and of ``blur = "shift"`` against 64
  sub-frames, on all pixels the blur changes and on the objects' outlines.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.sim import exposure, lens, sensor
from stackpick_sim.sim.camera import WristCamera
from stackpick_sim.sim.stacks import Scene, generate_scene

RESULTS = Path(__file__).resolve().parent / "results"
#: Each feature on its own, as realistic.toml sets it, on top of the paper scene.
FEATURES: dict[str, list[str]] = {
    "exposure 4 ms, 4 sub-frames": ["camera.exposure_s=0.004", "camera.blur_subframes=4"],
    "exposure 4 ms, shift": ["camera.exposure_s=0.004", 'camera.blur="shift"'],
    "distortion": ["camera.distortion=[-0.2, 0.05, 0.0005, -0.0003, 0.0]"],
    "sensor noise": ["camera.full_well=10000.0", "camera.read_noise=5.0", "camera.gain=2.0"],
    "vignetting": ["camera.vignetting=0.25"],
    "JPEG 90": ["camera.jpeg_quality=90"],
    "shadows, 1 lamp 1024 px": ["camera.shadows=true", "lights.shadow_lamps=1"],
    "shadows, 1 lamp 512 px": ["camera.shadows=true", "lights.shadow_lamps=1",
                               "lights.shadow_map_px=512"],
    "shadows, 1 lamp 256 px": ["camera.shadows=true", "lights.shadow_lamps=1",
                               "lights.shadow_map_px=256"],
    "shadows, 4 lamps 1024 px": ["camera.shadows=true"],
    "textured belt": ["conveyor.texture=true"],
}


def ms_per_frame(scenes: dict[str, Scene], rounds: int) -> dict[str, float]:
    """Median CPU ms (this process, all its threads: Mesa's renderer runs several) of one
    ``render(rng)`` of each scene's camera. Frames are taken in turns, one of each scene per
    round after two warm-up rounds; CPU time rather than wall time, since on a shared
    machine the wall time of a frame swings with the others' load."""
    cameras = {name: WristCamera(scene.cell) for name, scene in scenes.items()}
    rng = np.random.default_rng(0)
    times: dict[str, list[float]] = {name: [] for name in scenes}
    try:
        for r in range(rounds + 2):
            for name, camera in cameras.items():
                t0 = time.process_time()
                camera.render(rng)
                if r >= 2:
                    times[name].append(time.process_time() - t0)
    finally:
        for camera in cameras.values():
            camera.close()
    return {name: 1e3 * statistics.median(t) for name, t in times.items()}


#: ``realistic`` with one choice changed, to weigh it against the frame budget.
REALISTIC_VARIANTS: dict[str, list[str]] = {
    "256 px shadow map": ["lights.shadow_map_px=256"],
    "no shadows": ["camera.shadows=false"],
}
#: The stages of a frame, as (label, module, function name): each is timed where the camera
#: calls it.
STAGES: tuple[tuple[str, object, str], ...] = (
    ("blur: image motion", exposure, "image_shift"), ("blur: smear", exposure, "smear"),
    ("lens: remap", lens, "distort"), ("vignetting", sensor, "vignette"),
    ("sensor: noise", sensor, "expose"), ("quantisation", sensor, "quantise"),
    ("JPEG", sensor, "jpeg"))


def stage_ms(scene: Scene, rounds: int) -> dict[str, float]:
    """Median CPU ms per frame of each stage of ``scene``'s frame, MuJoCo's render included
    (``render``), and of the whole frame (``frame``)."""
    times: dict[str, list[float]] = {}

    def timed(label: str, f: Callable[..., object]) -> Callable[..., object]:
        def call(*args: object, **kw: object) -> object:
            t0 = time.process_time()
            try:
                return f(*args, **kw)
            finally:
                times.setdefault(label, []).append(time.process_time() - t0)
        return call

    saved = [(module, name, getattr(module, name)) for _, module, name in STAGES]
    camera = WristCamera(scene.cell)
    renderer = camera._renderer  # the benchmark times MuJoCo's own render too
    render = renderer.render
    rng = np.random.default_rng(0)
    try:
        for label, module, name in STAGES:
            setattr(module, name, timed(label, getattr(module, name)))
        renderer.render = timed("render", render)
        for r in range(rounds + 2):
            if r == 2:
                times.clear()
            timed("frame", camera.render)(rng)
    finally:
        for module, name, f in saved:
            setattr(module, name, f)
        renderer.render = render
        camera.close()
    return {label: 1e3 * sum(t) / rounds for label, t in times.items()}


def shadow_map_errors(seed: int) -> dict[str, float]:
    """Mean grey-level difference of ``realistic``'s frame with a 256 or 512 px shadow map
    from the frame with a 1024 px map, on the pixels where shadows on and off differ by more
    than 5 grey levels (no noise)."""
    def frame(*sets: str) -> np.ndarray:
        camera = WristCamera(generate_scene(load_scene("realistic", list(sets)), seed).cell)
        try:
            return camera.render().astype(float)
        finally:
            camera.close()

    ref = frame("lights.shadow_map_px=1024")
    shaded = np.abs(ref - frame("camera.shadows=false")).max(axis=2) > 5
    return {f"{px} px": float(np.abs(frame(f"lights.shadow_map_px={px}") - ref)
                              .max(axis=2)[shaded].mean()) for px in (256, 512)}


def _moving(scene: Scene, speed: float) -> None:
    cell = scene.cell
    cell.set_belt_speed(speed)
    for o in cell.objects:
        cell.data.qvel[o.dof_adr:o.dof_adr + 6] = 0.0
        cell.data.qvel[o.dof_adr + 1] = speed


def _outlines(seg: np.ndarray) -> np.ndarray:
    """Pixels within 2 px of a boundary between two objects or an object and the rest."""
    kernel = np.ones((5, 5), np.uint8)
    grown = cv2.dilate(seg.astype(np.float32), kernel)
    shrunk = cv2.erode(seg.astype(np.float32), kernel)
    return np.asarray(grown != shrunk)


def blur_errors(cfg: SceneConfig, seed: int, speed: float,
                exposure_s: float) -> dict[str, dict[str, float]]:
    """Grey-level errors of each blur rendering against 64 sub-frames: on every pixel the
    blur changes (``all``, belt texture included) and on the object outlines (``outlines``)."""
    scene = generate_scene(cfg, seed)
    _moving(scene, speed)
    cell = scene.cell

    def frame(**kw: object) -> np.ndarray:
        cell.cfg = replace(cfg, camera=replace(cfg.camera, **{"exposure_s": exposure_s, **kw}))
        camera = WristCamera(cell)
        try:
            return camera.render().astype(float)
        finally:
            camera.close()

    sharp = frame(exposure_s=0.0)
    camera = WristCamera(cell)
    seg = camera.segmentation()
    camera.close()
    ref = frame(blur="subframes", blur_subframes=64)
    changed = np.abs(ref - sharp).max(axis=2) > 2
    masks = {"all": changed, "outlines": changed & _outlines(seg)}
    variants: dict[str, Callable[[], np.ndarray]] = {"no blur": lambda: sharp}
    for n in (2, 4, 8, 16):
        variants[f"subframes {n}"] = lambda n=n: frame(blur="subframes",  # type: ignore[misc]
                                                       blur_subframes=n)
    variants["shift"] = lambda: frame(blur="shift")
    out = {}
    for name, make in variants.items():
        err = np.abs(make() - ref).max(axis=2)
        out[name] = {f"{k} {stat}": float(f(err[m])) for k, m in masks.items()
                     for stat, f in (("mean", np.mean),
                                     ("p99", lambda x: np.percentile(x, 99)))}
    cell.cfg = cfg
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=20000)
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args()
    configs = {"paper": load_scene("paper"), "realistic": load_scene("realistic")}
    configs.update({f"realistic, {name}": load_scene("realistic", sets)
                    for name, sets in REALISTIC_VARIANTS.items()})
    configs.update({f"paper + {name}": load_scene("paper", sets)
                    for name, sets in FEATURES.items()})
    costs = ms_per_frame({name: generate_scene(cfg, args.seed)
                          for name, cfg in configs.items()}, args.frames)
    for name, ms in costs.items():
        print(f"{name}: {ms:.1f} CPU ms/frame", flush=True)
    stages = stage_ms(generate_scene(configs["realistic"], args.seed), args.frames)
    shadow_maps = shadow_map_errors(args.seed)
    blur_cfg = load_scene("paper", ["conveyor.texture=true"])
    blur = {f"{v} m/s, {1e3 * e:g} ms": blur_errors(blur_cfg, args.seed, v, e)
            for v, e in ((0.1, 0.004), (0.3, 0.004), (0.3, 0.02))}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "camera.json").write_text(json.dumps(
        {"seed": args.seed, "frames": args.frames, "ms_per_frame": costs,
         "realistic_stages_ms": stages, "shadow_map_error": shadow_maps, "blur": blur},
        indent=1))
    base = costs["paper"]
    lines = ["# Camera model: cost per frame and motion-blur error", "",
             f"`python benchmarks/bench_camera.py --seed {args.seed} --frames {args.frames}` "
             "(one run, one seed's pile per scene, frames taken in turns, median CPU time of "
             "this process over the rounds; a 2-core machine shared with other jobs).", "",
             "| frame | CPU ms/frame | x paper |", "|---|---|---|"]
    lines += [f"| {name} | {ms:.1f} | {ms / base:.2f} |" for name, ms in costs.items()]
    lines += ["", "Where the realistic frame's time goes (CPU ms per frame, mean over the rounds "
              "of a separate run of its camera):", "", "| stage | CPU ms/frame |", "|---|---|"]
    lines += [f"| {name} | {ms:.2f} |" for name, ms in stages.items()]
    cam = configs["realistic"].camera
    per_grey = cam.full_well / 255.0 / cam.gain
    noise = float(np.sqrt(128 * per_grey + cam.read_noise**2) / per_grey)
    lines += ["", "Shadow map size: mean grey-level difference from the frame with a 1024 px "
              "map, on the pixels the shadows change by more than 5 grey levels (realistic, "
              f"no noise; its sensor's noise at grey level 128: {noise:.2f} std):", "",
              "| map | mean difference |", "|---|---|"]
    lines += [f"| {name} | {err:.2f} |" for name, err in shadow_maps.items()]
    lines += ["", "Blur error against 64 sub-frames, grey levels (0-255, the largest of the "
              "three channels), on every pixel the blur changes (belt texture included) and "
              "on the object outlines:", "",
              "| belt, exposure | rendering | all: mean | all: p99 | outlines: mean | "
              "outlines: p99 |", "|---|---|---|---|---|---|"]
    for case, rows in blur.items():
        lines += [f"| {case} | {name} | {r['all mean']:.2f} | {r['all p99']:.1f} | "
                  f"{r['outlines mean']:.2f} | {r['outlines p99']:.1f} |"
                  for name, r in rows.items()]
    (args.out / "camera.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
