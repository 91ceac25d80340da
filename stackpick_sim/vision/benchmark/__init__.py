"""Detection benchmark: frames with ground truth, methods, scoring and reports.

:mod:`frames` loads a ``stackpick dataset`` directory or renders frames; :mod:`methods` wraps
our detector and the baselines; :mod:`scoring` scores one output on one frame; :mod:`report`
aggregates; :func:`run_benchmark` ties them together.
"""

from stackpick_sim.vision.benchmark.frames import BenchFrame, TruthFace
from stackpick_sim.vision.benchmark.methods import METHOD_NAMES, make_methods
from stackpick_sim.vision.benchmark.report import MethodRecord, markdown, summarise, table1
from stackpick_sim.vision.benchmark.runner import run_benchmark
from stackpick_sim.vision.benchmark.scoring import MethodOutput, score_frame

__all__ = [
    "METHOD_NAMES",
    "BenchFrame",
    "MethodOutput",
    "MethodRecord",
    "TruthFace",
    "make_methods",
    "markdown",
    "run_benchmark",
    "score_frame",
    "summarise",
    "table1",
]
