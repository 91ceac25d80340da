"""Figures of the digital twin: render rate, scene build + settle time, rejection rate, and how
often a pile has one top object or several. Writes benchmarks/results/scene_<scene>.md/.json.

    python benchmarks/bench_scene.py [--scene paper] [--seeds 0:50] [--frames 200]

The render rate is measured on one scene's look frame, with and without shadows, and as a
ratio to a bare MuJoCo scene (one box, one light) rendered at the same size in the same run,
so machines of different speed can be compared.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from stackpick_sim.cli.common import parse_seeds
from stackpick_sim.config.loader import load_scene
from stackpick_sim.sim.camera import WristCamera, make_renderer
from stackpick_sim.sim.ground_truth import frame_truth
from stackpick_sim.sim.stacks import generate_scene

BARE_SCENE = """<mujoco><worldbody><light pos="0 0 2"/>
<geom type="box" size=".1 .1 .1"/><camera name="c" pos="0 -1 1" xyaxes="1 0 0 0 .7 .7"/>
</worldbody></mujoco>"""


def frames_per_second(render: object, frames: int) -> float:
    """Renders per second of a zero-argument callable, after two warm-up calls."""
    for _ in range(2):
        render()  # type: ignore[operator]
    start = time.perf_counter()
    for _ in range(frames):
        render()  # type: ignore[operator]
    return frames / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="paper")
    parser.add_argument("--seeds", default="0:50")
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()
    cfg = load_scene(args.scene)

    build_s, attempts, reasons, tops, counts = [], [], Counter(), Counter(), Counter()
    retries: Counter[str] = Counter()
    for seed in parse_seeds(args.seeds):
        scene = generate_scene(cfg, seed)
        build_s.append(scene.build_wall_s)
        attempts.append(scene.attempts)
        reasons.update(scene.rejections)
        retries.update(scene.drop_retries)
        camera = WristCamera(scene.cell)
        truth = frame_truth(scene.cell, camera.segmentation())
        camera.close()
        n_top = len(truth.top_objects)
        tops["one" if n_top == 1 else "several" if n_top > 1 else "none"] += 1
        counts[len(truth.objects)] += 1
        print(f"seed {seed}: {scene.build_wall_s:.2f} s, {scene.attempts} attempt(s), "
              f"{n_top} top", file=sys.stderr)

    scene = generate_scene(cfg, parse_seeds(args.seeds)[0])
    cam = WristCamera(scene.cell)
    fps_plain = frames_per_second(cam.render, args.frames)
    shadowed = load_scene(args.scene, ["camera.shadows=true"])
    scene_s = generate_scene(shadowed, parse_seeds(args.seeds)[0])
    cam_s = WristCamera(scene_s.cell)
    fps_shadow = frames_per_second(cam_s.render, max(20, args.frames // 5))
    fps_noisy = frames_per_second(lambda: cam.render(np.random.default_rng(0)), args.frames)
    import mujoco  # after stackpick_sim, which defaults MUJOCO_GL to egl

    bare = mujoco.MjModel.from_xml_string(BARE_SCENE)
    bare_data = mujoco.MjData(bare)
    mujoco.mj_forward(bare, bare_data)
    bare_r = make_renderer(bare, cfg.camera.height, cfg.camera.width)

    def bare_render() -> None:
        bare_r.update_scene(bare_data, "c")
        bare_r.render()

    fps_bare = frames_per_second(bare_render, args.frames)
    total_attempts = sum(attempts)
    result = {
        "scene": cfg.name, "seeds": args.seeds, "size": [cfg.camera.width, cfg.camera.height],
        "render_fps_no_shadows": fps_plain, "render_fps_shadows": fps_shadow,
        "render_fps_with_noise_and_jitter": fps_noisy, "bare_scene_fps": fps_bare,
        "ratio_no_shadows_to_bare": fps_plain / fps_bare,
        "ratio_shadows_to_bare": fps_shadow / fps_bare,
        "build_settle_s_median": statistics.median(build_s),
        "build_settle_s_p95": float(np.percentile(build_s, 95)),
        "attempts_mean": statistics.mean(attempts),
        "rejection_rate": (total_attempts - len(attempts)) / total_attempts,
        "rejections_by_reason": dict(reasons.most_common()),
        "drop_retries_by_reason": dict(retries.most_common()),
        "drop_retries_per_scene": sum(retries.values()) / len(attempts),
        "top_objects": dict(tops), "object_counts": dict(sorted(counts.items())),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"scene_{cfg.name}.json").write_text(json.dumps(result, indent=1))
    n = len(attempts)
    md = [f"# Scene figures: {cfg.name}, seeds {args.seeds} ({n} scenes)", "",
          "| figure | value |", "|---|---|",
          f"| wrist camera {cfg.camera.width}x{cfg.camera.height}, no shadows | "
          f"{fps_plain:.0f} frames/s ({fps_plain / fps_bare:.2f}x a bare one-box scene) |",
          f"| same, with shadows | {fps_shadow:.0f} frames/s "
          f"({fps_shadow / fps_bare:.2f}x bare) |",
          f"| same, with pixel noise and light jitter | {fps_noisy:.0f} frames/s |",
          f"| bare one-box scene (baseline) | {fps_bare:.0f} frames/s |",
          f"| build + settle one scene, median (p95) | {statistics.median(build_s):.2f} s "
          f"({np.percentile(build_s, 95):.2f} s) |",
          f"| rejection rate (rejected / all attempts) | {result['rejection_rate']:.1%} "
          f"({total_attempts - n} of {total_attempts}) |",
          f"| whole piles rejected, by reason | "
          f"{', '.join(f'{k}: {v}' for k, v in reasons.most_common()) or 'none'} |",
          f"| single drops undone and redrawn, per scene (by reason) | "
          f"{sum(retries.values()) / n:.1f} ("
          f"{', '.join(f'{k}: {v}' for k, v in retries.most_common()) or 'none'}) |",
          f"| piles with one top object / several / none | {tops['one']} / {tops['several']} "
          f"/ {tops['none']} of {n} |",
          f"| objects per pile | {', '.join(f'{k}: {v}' for k, v in sorted(counts.items()))} |"]
    (args.out / f"scene_{cfg.name}.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
