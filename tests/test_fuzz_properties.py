"""Property-based checks: arbitrary arrays, image files, scene files and --set values end in
a result or one StackpickError (exit code 2 with one line), never another exception.

A few hundred examples in all; benchmarks/fuzz.py runs thousands per family.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from stackpick_sim.cli.main import main
from stackpick_sim.config.loader import known_keys, load_scene
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.paths import SCENES_DIR
from stackpick_sim.vision.detection import Detection
from stackpick_sim.vision.detector import DetectorConfig, detect

FAST = settings(max_examples=80, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

DTYPES = st.sampled_from(["uint8", "uint16", "int8", "int16", "int32", "uint32", "int64",
                          "float16", "float32", "float64", "bool", "complex64"])


@st.composite
def images(draw: st.DrawFn) -> np.ndarray:
    """Arrays of any small shape and dtype, with NaN/inf among floats, in any memory layout."""
    dtype = np.dtype(draw(DTYPES))
    shape = draw(hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=48))
    fill = draw(hnp.from_dtype(dtype))
    array = np.full(shape, fill, dtype)
    if array.size:
        flat = array.reshape(-1)
        picks = draw(st.lists(st.tuples(st.integers(0, flat.size - 1), hnp.from_dtype(dtype)),
                              max_size=20))
        for index, value in picks:
            flat[index] = value
    layout = draw(st.sampled_from(["c", "fortran", "strided", "reversed"]))
    if layout == "fortran":
        array = np.asfortranarray(array)
    elif layout == "strided" and array.ndim:
        array = np.repeat(array, 2, axis=0)[::2]
    elif layout == "reversed" and array.ndim:
        array = array[::-1]
    return array


@FAST
@given(images())
def test_detect_returns_a_result_or_one_stackpick_error(image: np.ndarray) -> None:
    try:
        result = detect(image, DetectorConfig())
    except StackpickError:
        return
    assert isinstance(result, Detection)


def _encoded(ext: str) -> bytes:
    rng = np.random.default_rng(0)
    ok, buf = cv2.imencode(ext, rng.integers(0, 255, (24, 32, 3), dtype=np.uint8))
    assert ok
    return buf.tobytes()


SEEDS = [_encoded(ext) for ext in (".png", ".jpg", ".tiff", ".bmp", ".webp", ".ppm")]


@st.composite
def image_files(draw: st.DrawFn) -> bytes:
    """Random bytes, or a valid image file cut short or with some bytes changed."""
    if draw(st.booleans()):
        return draw(st.binary(max_size=256))
    data = bytearray(draw(st.sampled_from(SEEDS)))
    for index, value in draw(st.lists(st.tuples(st.integers(0, len(data) - 1),
                                                st.integers(0, 255)), max_size=8)):
        data[index] = value
    return bytes(data[:draw(st.integers(0, len(data)))])


def _no_constant(name: str) -> None:
    raise AssertionError(f"{name} in JSON output")


@FAST
@given(data=image_files())
def test_detect_on_any_file_exits_0_or_2_with_one_line(
        data: bytes, capfd: pytest.CaptureFixture[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "x.png")
        Path(path).write_bytes(data)
        capfd.readouterr()
        code = main(["detect", path, "--json"])
    out, err = capfd.readouterr()
    assert code in (0, 2)
    if code == 2:
        assert err.count("\n") == 1 and "error:" in err and out == "", err
    else:
        assert err == ""
        json.loads(out, parse_constant=_no_constant)


PAPER = (SCENES_DIR / "paper.toml").read_text()
TOML_SNIPPETS = st.sampled_from(["[", "]", "=", '"', "'", "\n", "[[", "1e300", "-1", "nan",
                                 "inf", "true", "{", "}", ",", ".", "#", "\\", "\x00", "\xff",
                                 "[conveyor]\n", "extends = 'paper'\n", "x = 1\n"])


@st.composite
def scene_texts(draw: st.DrawFn) -> str:
    """paper.toml with a few pieces inserted, deleted or replaced."""
    text = PAPER
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        cut = draw(st.integers(0, 12))
        text = text[:at] + draw(TOML_SNIPPETS | st.text(max_size=6)) + text[at + cut:]
    return text


@FAST
@given(scene_texts())
def test_mutated_scene_files_load_or_raise_one_config_error(text: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.toml"
        path.write_bytes(text.encode("utf-8", "surrogatepass"))
        try:
            load_scene(str(path))
        except StackpickError as exc:  # anything else fails the property: a crash
            assert str(exc) and "\n" not in str(exc), "a config error is one line"


VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                   st.integers(-10**30, 10**30).map(str), TOML_SNIPPETS,
                   st.text(max_size=12), st.lists(st.floats(-10, 10), max_size=4).map(str))


@FAST
@given(st.sampled_from(known_keys()) | st.text(max_size=20), VALUES)
def test_set_values_load_or_raise_one_config_error(key: str, value: str) -> None:
    key = key.replace("*", "large")
    try:
        load_scene("paper", [f"{key}={value}"])
    except StackpickError as exc:  # anything else fails the property: a crash
        assert str(exc) and "\n" not in str(exc), "a config error is one line"
