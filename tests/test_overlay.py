"""Pictures for people: labels apart, outlines visible on every object colour, hidden faces
left out, the detector's overlay with labels, pose and legend."""

from __future__ import annotations

import numpy as np
import pytest

from stackpick_sim.geometry import CameraIntrinsics, Ellipse
from stackpick_sim.overlay import (
    OTHER_COLOUR,
    TOP_COLOUR,
    Label,
    bgr_canvas,
    detection_overlay,
    draw_ellipse,
    place_labels,
    truth_overlay,
)
from stackpick_sim.sim.ground_truth import FrameTruth, ObjectTruth
from stackpick_sim.vision.detection import DetectedEllipse, Detection
from stackpick_sim.vision.pose import Pose

K = CameraIntrinsics.from_fovy(45.0, 320, 240)


def _overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> int:
    return max(0, min(a[2], b[2]) - max(a[0], b[0])) * max(0, min(a[3], b[3]) - max(a[1], b[1]))


def test_labels_of_a_tight_pile_do_not_overlap_and_stay_in_the_image() -> None:
    # Five faces a few pixels apart (a pile seen at twice the size): their labels crowd.
    labels = [Label(f"obj{i} 100% TOP", TOP_COLOUR,
                    Ellipse(cx=300 + 6 * i, cy=200 + 4 * i, a=60, b=58, angle_deg=0))
              for i in range(5)]
    boxes = place_labels(labels, (640, 480))
    for i, a in enumerate(boxes):
        assert 0 <= a[0] and a[2] <= 640 and 0 <= a[1] and a[3] <= 480
        for b in boxes[i + 1:]:
            assert _overlap(a, b) == 0


#: Faces to draw on, BGR: the outlines' own colours, the paper scene's orange and blue
#: kinds, white, the belt's grey.
FACES = [TOP_COLOUR, OTHER_COLOUR, (64, 153, 217), (217, 153, 77), (255, 255, 255), (50, 50, 50)]


@pytest.mark.parametrize("face", FACES)
@pytest.mark.parametrize("colour", [TOP_COLOUR, OTHER_COLOUR])
def test_an_outline_shows_on_every_face_colour(colour: tuple[int, int, int],
                                               face: tuple[int, int, int]) -> None:
    image = np.zeros((100, 100, 3), np.uint8)
    image[:] = face
    draw_ellipse(image, Ellipse(cx=50, cy=50, a=30, b=20, angle_deg=0), colour, 1)
    contrast = np.abs(image.astype(int) - np.array(face)).max(axis=2)
    assert (contrast > 100).sum() > 100  # a dark halo or the colour itself stands out


def _object(name: str, visible: float, top: bool, cx: float) -> ObjectTruth:
    return ObjectTruth(name=name, type_name="large", radius=0.035, height=0.03,
                       ellipse=Ellipse(cx=cx, cy=120, a=30, b=28, angle_deg=0),
                       face_center_px=(cx, 120.0), face_center_cam=(0.0, 0.0, 0.3),
                       face_center_world=(0.4, 0.0, 0.13), face_normal_cam=(0.0, 0.0, 1.0),
                       theta_x_deg=0.0, theta_y_deg=0.0, tilt_deg=0.0,
                       visible_fraction=visible, supports=(), on_belt=True, is_top=top)


def test_a_face_hidden_entirely_is_not_drawn() -> None:
    image = np.full((240, 320, 3), 60, np.uint8)
    shown = [_object("obj0", 1.0, True, 80.0)]
    hidden = [*shown, _object("obj1", 0.0, False, 240.0)]
    a = truth_overlay(image, _frame(shown))
    b = truth_overlay(image, _frame(hidden))
    assert np.array_equal(a, b)
    c = truth_overlay(image, _frame([*shown, _object("obj1", 0.3, False, 240.0)]))
    assert not np.array_equal(a, c)  # a face 30 % visible is drawn


def _frame(objects: list[ObjectTruth]) -> FrameTruth:
    return FrameTruth(time=0.0, world_T_cam=np.eye(4), intrinsics=K, objects=tuple(objects))


def test_the_detection_overlay_is_twice_the_frame_with_pose_and_legend() -> None:
    image = np.full((240, 320, 3), 60, np.uint8)
    top = DetectedEllipse(ellipse=Ellipse(cx=160, cy=120, a=40, b=36, angle_deg=30),
                          segments=(), residual_px=0.2, support=0.93)
    other = DetectedEllipse(ellipse=Ellipse(cx=100, cy=100, a=30, b=30, angle_deg=0),
                            segments=(), residual_px=0.3, support=0.51)
    normal = np.array([0.3, 0.0, 0.95]) / np.linalg.norm([0.3, 0.0, 0.95])
    pose = Pose(x=160.0, y=120.0, theta_x_deg=0.0, theta_y_deg=17.0, depth_m=0.3,
                radius_m=0.035, normal_cam=normal, centre_cam=np.array([0.0, 0.0, 0.3]),
                wall_support=(1.0, 0.0))
    out = detection_overlay(image, Detection(ellipses=(top, other), top=0, pose=pose), K)
    assert out.shape[1] == 640 and out.shape[0] > 480  # 2x, and the legend strip below
    frame = out[:480]
    assert np.array_equal(bgr_canvas(image)[0, 0], frame[479, 639])  # a corner left alone
    green = np.all(frame == np.array(TOP_COLOUR, np.uint8), axis=2)
    assert green.sum() > 200  # the top outline and its cross
    # The normal arrow (white) leaves the centre towards -u: the outward normal of a face
    # whose inward normal leans to +x (camera frame).
    white = np.argwhere(np.all(frame >= 250, axis=2))
    assert white.size and white[:, 1].min() < 2 * 160 - 20
