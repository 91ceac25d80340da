"""docs/api.md runs: its ```python blocks in order (quick start, stepping, the minimal
estimator and controller, the Gymnasium loop), and the minimal stages drive real episodes."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes import run_episode
from stackpick_sim.sim.stacks import generate_scene

DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"
MODULE = "stackpick_api_doc"


@pytest.fixture(scope="module")
def doc_module() -> types.ModuleType:
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert len(blocks) == 5
    module = types.ModuleType(MODULE)
    sys.modules[MODULE] = module
    for block in blocks:
        if "gymnasium" in block and pytest.importorskip("gymnasium") is None:
            continue
        exec(compile(block, str(DOC), "exec"), module.__dict__)
    yield module
    del sys.modules[MODULE]


def test_quick_start_runs_the_pick_of_stackpick_run(doc_module: types.ModuleType) -> None:
    ns = doc_module.__dict__
    assert ns["top"].is_top and ns["top"].normal_cam is not None
    assert ns["record"].success and ns["record"].failure is None
    assert ns["reward"] == 1.0


def test_the_minimal_estimator_and_controller_drive_episodes(doc_module: types.ModuleType
                                                              ) -> None:
    cfg = load_scene("paper", ["episode.detector=oracle",
                               f"episode.estimator={MODULE}:BeltLine"])
    rec = run_episode(generate_scene(cfg, 1))
    assert rec.estimator == f"{MODULE}:BeltLine"
    assert rec.success, (rec.failure, rec.failure_detail)
    cfg = load_scene("paper", ["episode.detector=oracle",
                               f"episode.controller={MODULE}:PoseIK"])
    rec = run_episode(generate_scene(cfg, 1))
    assert rec.controller == f"{MODULE}:PoseIK"
    assert rec.failure != "error", rec.failure_detail
    assert "approach" in rec.phases and "servo" in rec.phases
