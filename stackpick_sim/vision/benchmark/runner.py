"""Run methods over frames: every method sees each frame in turn, one thread, timed calls."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import cv2
import numpy as np

from stackpick_sim.vision.benchmark.frames import BenchFrame
from stackpick_sim.vision.benchmark.methods import Method
from stackpick_sim.vision.benchmark.report import MethodRecord
from stackpick_sim.vision.benchmark.scoring import score_frame


def run_benchmark(frames: Iterable[BenchFrame], methods: list[Method]
                  ) -> tuple[list[BenchFrame], dict[str, MethodRecord]]:
    """Run each method on each frame (interleaved, so load drifts hit all methods alike).

    OpenCV runs single-threaded during the run (restored afterwards). Returns the frames
    (images dropped to save memory) and one record per method.
    """
    records = {m.name: MethodRecord(m.name) for m in methods}
    kept: list[BenchFrame] = []
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        for frame in frames:
            for m in methods:
                out = m.run(frame)
                records[m.name].outputs.append(out)
                records[m.name].scores.append(score_frame(out, frame))
            kept.append(replace(frame, image_rgb=np.zeros((0, 0, 3), np.uint8)))
    finally:
        cv2.setNumThreads(threads)
    return kept, records
