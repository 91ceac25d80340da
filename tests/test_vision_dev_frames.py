"""Pinned paper-scene frames (rendered by the simulator, with their ground truth; one with
both kinds grey) on which a detector step decides: the detector's choice is a true top face,
and without the step it is a whole lower face that the top rests on, or no face at all; a
refit of the top face on a lower outline is not reported beside it; no refit smaller than
any face in the depth range is reported."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from stackpick_sim.config.loader import load_scene
from stackpick_sim.config.scene_config import VisionCfg
from stackpick_sim.geometry import Ellipse, mask_iou
from stackpick_sim.vision import detector as detector_module
from stackpick_sim.vision import occlusion as occlusion_module
from stackpick_sim.vision.benchmark.frames import BenchFrame, load_frame
from stackpick_sim.vision.benchmark.methods import detector_config, make_methods
from stackpick_sim.vision.benchmark.scoring import MATCH_IOU
from stackpick_sim.vision.detector import TopObjectDetector
from stackpick_sim.vision.params import (
    FALLBACKS,
    CompleteParams,
    GateParams,
    TopParams,
    WholeRefitParams,
)

#: The paper scene's frames of seeds 857, 1374, 1438, 1769, 2241, 2333, 3032, 3070, 3120,
#: 3355, 3504, 3791, 3886, 30229 and 40091: PNG and ground-truth JSON as `stackpick dataset
#: --scene paper` writes them.
FRAMES = Path(__file__).parent / "data" / "paper_dev_frames"
#: The paper scene with both kinds light grey (GREY), frame of seed 70070.
GREY_FRAMES = Path(__file__).parent / "data" / "grey_dev_frames"
GREY = ("object_types.large.rgba=[0.7,0.7,0.7,1.0]", "object_types.small.rgba=[0.7,0.7,0.7,1.0]")


def _frame(seed: int, directory: Path = FRAMES, overrides: tuple[str, ...] = ()) -> BenchFrame:
    scene = load_scene("paper", overrides)
    kinds = tuple((t.radius, (t.rgba[0], t.rgba[1], t.rgba[2]), t.height)
                  for t in scene.object_types.values())
    return load_frame(directory, seed, scene.conveyor.top_z, scene.objects.max_face_height,
                      kinds)


def _top_iou(frame: BenchFrame) -> tuple[float, float]:
    """(IoU with the best true top face, with the best face that is not top) of the
    detector's choice."""
    found = TopObjectDetector(detector_config(frame)).detect(frame.image_rgb).top_ellipse
    assert found is not None
    top = max(mask_iou(found, f.ellipse, frame.shape) for f in frame.tops)
    other = max(mask_iou(found, f.ellipse, frame.shape) for f in frame.faces
                if not f.is_top and f.ellipse is not None)
    return top, other


def _chosen_top(seed: int, directory: Path = FRAMES, overrides: tuple[str, ...] = ()
                ) -> BenchFrame:
    """Frame ``seed``, asserting that the detector chooses a true top face on it."""
    frame = _frame(seed, directory, overrides)
    top, _ = _top_iou(frame)
    assert top > MATCH_IOU
    return frame


def _assert_missed(frame: BenchFrame) -> None:
    """The detector chooses no face on ``frame``."""
    missed = TopObjectDetector(detector_config(frame)).detect(frame.image_rgb)
    assert missed.top_ellipse is None, missed.reason


def _assert_lower_chosen(frame: BenchFrame) -> None:
    """The detector chooses a face on ``frame`` that is not a top face."""
    _, other = _top_iou(frame)
    assert other > MATCH_IOU


@pytest.mark.parametrize("seed", [857, 1769, 2241])
def test_rimmed_face_resting_on_the_chosen_face_takes_the_choice(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # The top face's fit takes in a same-colour lower face's sliver (its own rim inside it);
    # the face it rests on passes the rule. (On frame 857 a second fit of the top, cut short
    # with nothing crossing it, also leads to the top by the hidden-face check: both off.)
    frame = _chosen_top(seed)
    monkeypatch.setattr(detector_module, "select_resting_rimmed", lambda *a, **k: None)
    monkeypatch.setattr(detector_module, "hidden_by_no_outline", lambda *args: False)
    _assert_lower_chosen(frame)


def test_a_face_cut_short_with_nothing_crossing_it_leads_to_a_nearer_arc_face(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 857 without the rimmed-face step: the rule chooses a whole lower face; a second
    # fit of the top face fails on support alone (0.74) with nothing crossing it, so a face
    # of its colour may hide it, and a fit on pairs of arcs finds the top clearly nearer.
    monkeypatch.setattr(detector_module, "select_resting_rimmed", lambda *a, **k: None)
    frame = _chosen_top(857)
    monkeypatch.setattr(detector_module, "hidden_by_no_outline", lambda *args: False)
    _assert_lower_chosen(frame)


def test_a_face_behind_a_wall_does_not_cover_it(monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 2333: the top face, nearly square on, lies beside a lower face 2.5 cm farther
    # away; its wrong pose solution's wall band falls on that face in the image.
    frame = _chosen_top(2333)
    under = occlusion_module.under_another
    monkeypatch.setattr(occlusion_module, "under_another",
                        lambda faces, k, radius_of=None, **kw: under(faces, k, **kw))
    _assert_lower_chosen(frame)


@pytest.mark.parametrize("seed", [3504, 3886])
def test_top_face_broken_into_unfittable_arcs_is_found_from_pairs_of_them(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # The top face lies across faces of its colour: its whole outline is in the edge map, in
    # arcs of 10-30 px between the junctions whose own fits are too flat to keep.
    frame = _chosen_top(seed)
    monkeypatch.setattr(detector_module, "last_resort_arcs",
                        lambda pieces, *_: (tuple(pieces), list(range(len(pieces)))))
    # (When every face then reads as occluded, a fit of the top face on part of its outline
    # refits onto the whole face, and the whole-refit step finds the top too: off.)
    monkeypatch.setattr(detector_module, "_whole_refit",
                        lambda state, merged, choice, cues, config: (merged, choice))
    _assert_missed(frame)


@pytest.mark.parametrize("seed", [1374, 1438])
def test_top_face_linked_with_a_lower_silhouette_is_found_from_the_cut_chain(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # The top face lies on a face of its colour that shows a sliver beyond it: Canny runs the
    # top's outline on into that sliver's silhouette in one chain, and the top's own faint
    # boundary ends near the two points where the outlines meet.
    frame = _chosen_top(seed)
    monkeypatch.setattr(detector_module, "split_at_junctions",
                        lambda chains, *_: [[c] for c in chains])
    # (When every face then reads as occluded, the lower face's fit round the top and its
    # sliver holds the top face inside it, and its inner refit finds the top too, as does
    # the whole-refit step from a fit of the top on part of its outline: off.)
    monkeypatch.setattr(detector_module, "_inner_face",
                        lambda state, merged, choice, cues, config: (merged, choice))
    monkeypatch.setattr(detector_module, "_whole_refit",
                        lambda state, merged, choice, cues, config: (merged, choice))
    _assert_missed(frame)


def test_unobstructed_pair_of_unfittable_arcs_is_the_last_resort(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 3032: the top face's boundary with a lower face of its colour shows no edge
    # contrast at all (support ~0.8), so even its fit on pairs of its arcs fails the rule;
    # nothing crosses it and nothing ends on it.
    frame = _chosen_top(3032)
    monkeypatch.setattr(detector_module, "select_unobstructed", lambda *a, **k: None)
    # The last fallback still finds it: of the faces at least half visible, it lies clearly
    # nearest, and its fit on pairs of its arcs is cut short by nothing.
    top, _ = _top_iou(frame)
    assert top > MATCH_IOU
    monkeypatch.setattr(detector_module, "_nearest_cut",
                        lambda found, merged, choice, cues, config: (merged, choice))
    _assert_missed(frame)


def test_last_pair_with_its_own_rim_inside_is_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 3355: a large top face (semi-axis ~65 px) over faces of its colour; its fit from
    # pairs of its arcs shows its whole outline but keeps its own faint rim inside it.
    frame = _chosen_top(3355)
    monkeypatch.setattr(detector_module, "select_rimmed", lambda *a, **k: None)
    # (The whole-refit step refits that fit onto the face's own outline and finds it too:
    # off.)
    monkeypatch.setattr(detector_module, "_whole_refit",
                        lambda state, merged, choice, cues, config: (merged, choice))
    _assert_missed(frame)


@pytest.mark.parametrize("seed", [3791, 30229])
def test_a_face_from_arc_pairs_clearly_nearer_than_a_fallback_choice_wins(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 3791: no fit passes the rule; the contrast refit of a lower, nearly whole face
    # passes, and the top face, which the merge never fitted, is ~4 cm nearer the camera.
    # Frame 30229: the top face lies across two faces of its colour and shade, whose
    # boundaries with it show no edge: it is never fitted, and a lower face it hides passes
    # the unobstructed fallback (nothing crosses it); its fit on pairs of its arcs is ~2 cm
    # nearer. (On frame 3791 the face completion, after the unclear first choice, proposes
    # the top face too: off.)
    frame = _chosen_top(seed)
    monkeypatch.setattr(detector_module, "_nearer_arc_face",
                        lambda merged, choice, *a, **k: (merged, choice))
    monkeypatch.setattr(detector_module, "complete_faces", lambda *a, **k: [])
    _assert_lower_chosen(frame)


def test_an_unobstructed_face_from_arc_pairs_clearly_nearer_than_a_refit_wins(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 3120: the contrast refit of a lower, nearly whole face passes; the top face lies
    # on a face of its colour, its fit from pairs of its arcs shows support ~0.87 (its faint
    # boundary with that face) with nothing crossing it, and is clearly nearer.
    frame = _chosen_top(3120)
    monkeypatch.setattr(detector_module, "unobstructed", lambda ev: False)
    _assert_lower_chosen(frame)


def test_a_refit_of_the_top_face_on_a_lower_outline_is_not_reported(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 3070: the top face lies on a lower face of its colour; a fit on arcs of both
    # outlines (mask IoU ~0.8 with the top face) is reported beside the top unless dropped.
    frame = _frame(3070)

    def second_fits_of_the_top() -> int:
        found = TopObjectDetector(detector_config(frame)).detect(frame.image_rgb)
        assert found.top is not None
        assert max(mask_iou(found.top_ellipse, f.ellipse, frame.shape)
                   for f in frame.tops) > MATCH_IOU
        return sum(max(mask_iou(d.ellipse, f.ellipse, frame.shape) for f in frame.tops)
                   > MATCH_IOU for i, d in enumerate(found.ellipses) if i != found.top)

    assert second_fits_of_the_top() == 0
    monkeypatch.setattr(detector_module, "_top_misfits", lambda *a, **k: set())
    assert second_fits_of_the_top() == 1


#: The top stage without its face completion.
NO_COMPLETION = CompleteParams(enabled=False)


def _with_top(frame: BenchFrame, top: TopParams) -> TopObjectDetector:
    return TopObjectDetector(replace(detector_config(frame), top=top))


def test_the_rest_check_is_an_option_of_the_top_stage() -> None:
    # Frame 857, as in the rest check's test above, switched off by its setting (with the
    # hidden-face check, which also reaches this frame's top).
    frame = _chosen_top(857)
    found = _with_top(frame, TopParams(rest_check=False, hidden_check=False)
                      ).detect(frame.image_rgb)
    assert found.top_ellipse is not None
    assert max(mask_iou(found.top_ellipse, f.ellipse, frame.shape) for f in frame.faces
               if not f.is_top and f.ellipse is not None) > MATCH_IOU


@pytest.mark.parametrize(("seed", "dropped"), [(3504, ("arc_pairs", "all_arcs", "nearest_cut")),
                                                (3355, ("all_arcs",))])
def test_fallbacks_are_options_of_the_top_stage(seed: int, dropped: tuple[str, ...]) -> None:
    # Frames whose top face only the arc-pair fallbacks find (see the tests above; on frame
    # 3504 the face completion proposes it too, on frame 3355 the whole-refit step: off):
    # without those fallbacks, or without any, no face is chosen.
    frame = _chosen_top(seed)
    kept = tuple(f for f in FALLBACKS if f not in dropped)
    for fallbacks in (kept, ()):
        found = TopObjectDetector(replace(detector_config(frame), top=TopParams(
            fallbacks=fallbacks), complete=NO_COMPLETION,
            whole_refit=WholeRefitParams(enabled=False))).detect(frame.image_rgb)
        assert found.top_ellipse is None, (fallbacks, found.reason)


def test_benchmark_methods_take_a_scenes_vision_settings() -> None:
    # Frame 3504's top face only the arc-pair fallbacks and the face completion find: without
    # them, ours misses.
    frame = _chosen_top(3504)
    [ours] = make_methods(["ours"], vision=VisionCfg(top=TopParams(fallbacks=()),
                                                     complete=NO_COMPLETION))
    assert ours.run(frame).top is None
    [ours] = make_methods(["ours"], vision=VisionCfg())
    assert ours.run(frame).top is not None


def test_a_lean_found_on_one_fit_of_a_face_holds_for_its_other_fit(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # Frame 40091: a whole lower face is fitted twice; the top cylinder leans on it edge to
    # edge, and the rest test finds the lean on one fit only (contact normal 0.8 up against
    # 0.2 for the other fit). The verdict holds for both fits (left on the other, that fit
    # would tie with the top face in support, which the top face's longer semi-major axis
    # then wins).
    frame = _chosen_top(40091)
    shared = occlusion_module._shared_by_refits
    verdicts: list[tuple[list[bool], list[bool]]] = []

    def spy(faces: list[Ellipse], under: list[bool]) -> list[bool]:
        verdicts.append((under, shared(faces, under)))
        return verdicts[-1][1]

    monkeypatch.setattr(occlusion_module, "_shared_by_refits", spy)
    TopObjectDetector(detector_config(frame)).detect(frame.image_rgb)
    assert any(sum(after) > sum(before) for before, after in verdicts)


def test_no_contrast_refit_below_the_size_gate_is_chosen() -> None:
    # Grey frame 70070: kinds of the belt's hue; a lower face's refit on its own contrast
    # shrinks to the arc of a sliver (semi-major axis below any face's in the depth range)
    # and passed the rule in place of the top face.
    frame = _chosen_top(70070, GREY_FRAMES, GREY)
    found = TopObjectDetector(detector_config(frame)).detect(frame.image_rgb)
    k = frame.intrinsics
    far = frame.depth_range_m[1]
    smallest = GateParams().slack[0] * min(k.fx, k.fy) * 0.025 / far
    assert all(d.ellipse.a >= smallest for d in found.ellipses)
