"""The detector's worst case: stage times on procedural stress images, and peak memory.

    python benchmarks/bench_vision_stress.py [--seeds 0:20] [--size 320x240] [--memory]

Runs :func:`stackpick_sim.vision.detect` (default configuration, one thread) on every
kind of :mod:`stress_images` (noise, textures, many small ellipses, targets and road signs,
photo-like clutter) for each seed, after one warm-up detection (the compiled kernels' load).
Stage times are read on the thread's CPU clock (``Detection.timings_ms`` with the detector's
clock switched to ``time.thread_time``): on a machine shared with other jobs preemption then
adds nothing. Prints p50 / p99 / max per stage over all images, and the slowest images.

``--memory`` also runs one detection per image in a fresh process each (4000x3000 frames
of tens of thousands of small ellipses and of clutter among them) and prints the process's
peak resident memory before and after it.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from stress_images import KINDS, stress_image

STAGES = ("roi", "edges", "segments", "fitting", "merging", "refine", "top", "pose", "total")

#: Run in a fresh process on an image saved as .npy: peak RSS (MB) after the imports and the
#: image's load, and after one detection.
MEMORY_WORKER = r"""
import sys
import cv2
import numpy as np
cv2.setNumThreads(1)
from stackpick_sim.vision import detect
from stackpick_sim.vision.kernels import warm_up
warm_up()
image = np.load(sys.argv[1])
def peak_mb():  # VmHWM: this process's own peak (ru_maxrss keeps the forking parent's)
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmHWM")) / 1024
before = peak_mb()
result = detect(image)
after = peak_mb()
print(f"{before:.0f} {after:.0f} {len(result.ellipses)}")
"""


def timings(seeds: range, width: int, height: int) -> list[tuple[str, int, dict[str, float]]]:
    """(kind, seed, CPU ms per stage) of each stress image."""
    import cv2

    cv2.setNumThreads(1)
    time.perf_counter = time.thread_time  # the detector's stage clock: this thread's CPU
    from stackpick_sim.vision import detect
    from stackpick_sim.vision.kernels import warm_up

    warm_up()  # the kernels' load (each kernel loads on its first call)
    out = []
    for kind in KINDS:
        for seed in seeds:
            result = detect(stress_image(kind, seed, width, height))
            out.append((kind, seed, dict(result.timings_ms)))
    return out


def memory(kinds_sizes: list[tuple[str, int, int]]) -> None:
    """Print the peak resident memory of one detection per (kind, width, height)."""
    print("\n| image | peak RSS after imports, MB | peak RSS after detect, MB | ellipses |")
    print("|---|---|---|---|")
    for kind, w, h in kinds_sizes:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "image.npy"
            np.save(path, stress_image(kind, 0, w, h))
            run = subprocess.run([sys.executable, "-c", MEMORY_WORKER, str(path)],
                                 check=True, capture_output=True, text=True)
        before, after, count = run.stdout.split()
        print(f"| {kind} {w}x{h} | {before} | {after} | {count} |")


def main() -> int:
    """Run the stress set and print the tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", default="0:20", help="START:STOP per kind (default 0:20)")
    p.add_argument("--size", default="320x240", help="WxH (default 320x240)")
    p.add_argument("--memory", action="store_true", help="also measure peak memory")
    args = p.parse_args()
    start, stop = (int(x) for x in args.seeds.split(":"))
    width, height = (int(x) for x in args.size.split("x"))
    rows = timings(range(start, stop), width, height)
    print(f"Detector CPU ms per stage on {len(rows)} stress images ({len(KINDS)} kinds x "
          f"seeds {args.seeds}, {width}x{height}):\n")
    print("| stage | p50 | p99 | max |")
    print("|---|---|---|---|")
    for s in STAGES:
        t = np.array([r[2].get(s, 0.0) for r in rows])
        print(f"| {s} | {np.percentile(t, 50):.2f} | {np.percentile(t, 99):.2f} | "
              f"{t.max():.2f} |")
    print("\nSlowest images (total CPU ms):")
    for kind, seed, t in sorted(rows, key=lambda r: -r[2].get("total", 0.0))[:5]:
        print(f"  {kind} seed {seed}: {t.get('total', 0.0):.1f}")
    for kind in KINDS:
        t = np.array([r[2].get("total", 0.0) for r in rows if r[0] == kind])
        print(f"  {kind}: p50 {np.percentile(t, 50):.1f}, max {t.max():.1f}")
    if args.memory:
        memory([("small_ellipses", 320, 240), ("clutter", 640, 480),
                ("small_ellipses", 4000, 3000), ("clutter", 4000, 3000)])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
