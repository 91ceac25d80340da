"""``stackpick replay --video``: an H.264 file browsers play, with readable frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stackpick_sim.cli.main import main
from stackpick_sim.episodes.video import BANNER_HEIGHT, VIEW_SIZE, outcome_text

imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")

SEED = 3


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "run"
    assert main(["run", "--scene", "paper", "--seeds", str(SEED), "--detector", "oracle",
                 "--out", str(out), "--quiet"]) == 0
    path = out / f"replay_{SEED}.mp4"
    assert main(["replay", str(out), str(SEED), "--video", str(path), "--truth"]) == 0
    return path


def _frames(path: Path) -> tuple[dict, list[np.ndarray]]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]
    return meta, frames


def test_the_video_is_h264_yuv420p_of_even_size(video: Path) -> None:
    meta, frames = _frames(video)
    assert meta["codec"].startswith("h264")
    assert meta["pix_fmt"].startswith("yuv420p")
    w, h = meta["size"]
    assert w % 2 == 0 and h % 2 == 0 and w == 2 * VIEW_SIZE[0]
    assert len(frames) > 20


def test_no_frame_shows_a_black_wrist_camera(video: Path) -> None:
    _, frames = _frames(video)
    for frame in frames[:5]:
        wrist = frame[BANNER_HEIGHT:BANNER_HEIGHT + VIEW_SIZE[1], :VIEW_SIZE[0]]
        assert wrist.mean() > 20  # the belt and the pile, not an empty frame


def test_the_banner_text_is_large_enough_to_read(video: Path) -> None:
    _, frames = _frames(video)
    first_line = frames[0][: BANNER_HEIGHT // 2, : VIEW_SIZE[0]].max(axis=2)
    rows = np.flatnonzero((first_line > 150).sum(axis=1) > 2)
    assert rows.size and rows.max() - rows.min() >= 14  # letters at least 14 px high


def test_outcome_text_names_the_reason_and_its_detail() -> None:
    assert outcome_text({"success": True}) == "success"
    assert outcome_text({"success": False, "failure": "lift_timeout",
                         "failure_detail": "target toppled"}) == "lift timeout: target toppled"
