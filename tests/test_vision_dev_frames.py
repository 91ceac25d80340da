"""Pinned paper-scene development frames (rendered by the simulator, with their ground truth)
on which a top-rule step decides: the detector's choice is a true top face, and without the
step it is a whole lower face that the top rests on."""

from __future__ import annotations

from pathlib import Path

import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.geometry import mask_iou
from stackpick_sim.vision import detector as detector_module
from stackpick_sim.vision import occlusion as occlusion_module
from stackpick_sim.vision.benchmark.frames import BenchFrame, load_frame
from stackpick_sim.vision.benchmark.methods import detector_config
from stackpick_sim.vision.benchmark.scoring import MATCH_IOU
from stackpick_sim.vision.detector import TopObjectDetector

#: Frames copied from the development data sets ds_paper_dev4 (857), ds_paper_h1k (1769) and
#: ds_paper_h2k (2241, 2333), PNG and ground-truth JSON as `stackpick dataset` wrote them.
FRAMES = Path(__file__).parent / "data" / "paper_dev_frames"


def _frame(seed: int) -> BenchFrame:
    scene = load_scene("paper")
    kinds = tuple((t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
                  for t in scene.object_types.values())
    return load_frame(FRAMES, seed, scene.conveyor.top_z, scene.objects.max_face_height, kinds)


def _top_iou(frame: BenchFrame) -> tuple[float, float]:
    """(IoU with the best true top face, with the best face that is not top) of the
    detector's choice."""
    found = TopObjectDetector(detector_config(frame)).detect(frame.image_rgb).top_ellipse
    assert found is not None
    top = max(mask_iou(found, f.ellipse, frame.shape) for f in frame.tops)
    other = max(mask_iou(found, f.ellipse, frame.shape) for f in frame.faces
                if not f.is_top and f.ellipse is not None)
    return top, other


@pytest.mark.parametrize("seed", [857, 1769, 2241])
def test_rimmed_face_resting_on_the_chosen_face_takes_the_choice(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # The top face's fit takes in a same-colour lower face's sliver (its own rim inside it);
    # the face it rests on passes the rule.
    frame = _frame(seed)
    top, _ = _top_iou(frame)
    assert top > MATCH_IOU
    monkeypatch.setattr(detector_module, "select_resting_rimmed", lambda *a, **k: None)
    _, other = _top_iou(frame)
    assert other > MATCH_IOU


def test_a_face_behind_a_wall_does_not_cover_it(monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 2333: the top face, nearly square on, lies beside a lower face 2.5 cm farther
    # away; its wrong pose solution's wall band falls on that face in the image.
    frame = _frame(2333)
    top, _ = _top_iou(frame)
    assert top > MATCH_IOU
    under = occlusion_module.under_another
    monkeypatch.setattr(occlusion_module, "under_another",
                        lambda faces, k, radius_of=None: under(faces, k))
    _, other = _top_iou(frame)
    assert other > MATCH_IOU
