"""The cover check's coarse screen: verdicts read on the coarse directions alone are the
exact test's."""

from __future__ import annotations

from unittest import mock

import numpy as np

from stackpick_sim.geometry import CameraIntrinsics, Ellipse, project_circle
from stackpick_sim.vision import resting
from stackpick_sim.vision.resting import cover_check

K = CameraIntrinsics.from_fovy(45.0, 320, 240)
RADII = {0.035: 0.03, 0.025: 0.025}  # the paper scene's kinds: radius -> height (m)


def _faces(rng: np.random.Generator, n: int) -> tuple[list[Ellipse], dict[Ellipse, float]]:
    """``n`` tilted faces of either kind a few centimetres apart under the camera, and each
    face's radius."""
    faces: list[Ellipse] = []
    radius: dict[Ellipse, float] = {}
    while len(faces) < n:
        r = float(rng.choice(list(RADII)))
        tilt = rng.normal(0.0, 0.5, 3)
        normal = np.array([tilt[0], tilt[1], -1.0])
        centre = np.array([*rng.uniform(-0.05, 0.05, 2), rng.uniform(0.2, 0.26)])
        try:
            face = project_circle(centre, normal / np.linalg.norm(normal), r, K)
        except ValueError:
            continue
        faces.append(face)
        radius[face] = r
    return faces, radius


def test_screened_verdicts_are_the_exact_tests() -> None:
    rng = np.random.default_rng(11)
    decided: list[bool] = []
    screen = resting._clear_on_coarse

    def spy(*args: object) -> bool:
        decided.append(screen(*args))  # type: ignore[arg-type]
        return decided[-1]

    for _ in range(60):
        faces, radius = _faces(rng, int(rng.integers(2, 5)))
        n = len(faces)
        triples = [(i, s, j) for i in range(n) for s in (0, 1) for j in range(n) if i != j]
        possible = cover_check(faces, K, radius.get, RADII.get)
        with mock.patch.object(resting, "_clear_on_coarse", spy):
            got = possible(triples)
        with mock.patch.object(resting, "_clear_on_coarse", return_value=False):
            want = possible(triples)
        assert got == want
    # Both kinds of call occur: the screen decides some, the exact test the others (some of
    # which rule a cover out).
    assert any(decided) and not all(decided)
