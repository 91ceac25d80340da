"""Reading and writing image files: what is refused, with one line, before any damage."""

from __future__ import annotations

import errno
import os
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from stackpick_sim.cli.detect_cmd import draw_overlay
from stackpick_sim.exceptions import ImageError, OutputError
from stackpick_sim.files import write_text
from stackpick_sim.image_io import MAX_IMAGE_PIXELS, read_image, write_image
from stackpick_sim.vision.detection import Detection


def png_header(width: int, height: int, idat: bytes = b"\0" * 100) -> bytes:
    """A PNG whose header declares ``width`` x ``height`` RGB8 with too little data."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(idat))
            + chunk(b"IEND", b""))


def test_missing_file_with_a_non_utf8_name_is_an_image_error(tmp_path: Path) -> None:
    path = os.path.join(os.fsencode(tmp_path), b"nothere\xff.png")
    with pytest.raises(ImageError, match=r"nothere\\xff\.png.*No such file"):
        read_image(os.fsdecode(path))


def test_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "f.png"
    os.mkfifo(fifo)
    with pytest.raises(ImageError, match="not a regular file"):
        read_image(fifo)


def test_a_directory_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ImageError, match="directory"):
        read_image(tmp_path)


@pytest.mark.parametrize("size", [(100_000, 100_000), (20_000, 20_000), (4097, 4096)])
def test_a_header_declaring_too_many_pixels_is_refused_before_decoding(
        size: tuple[int, int], tmp_path: Path) -> None:
    path = tmp_path / "big.png"
    path.write_bytes(png_header(*size))
    with pytest.raises(ImageError, match=f"{size[0]}x{size[1]} px.*{MAX_IMAGE_PIXELS}"):
        read_image(path)


def test_a_tiff_header_declaring_too_many_pixels_is_refused(tmp_path: Path) -> None:
    ok, buf = cv2.imencode(".tiff", np.zeros((1, 20_000), np.uint8))
    assert ok
    data = bytearray(buf.tobytes())
    # ImageLength (tag 257) of the first IFD: 1 -> 20000 rows.
    ifd = struct.unpack("<I", data[4:8])[0]
    for i in range(struct.unpack("<H", data[ifd:ifd + 2])[0]):
        entry = ifd + 2 + 12 * i
        if struct.unpack("<H", data[entry:entry + 2])[0] == 257:
            data[entry + 8:entry + 12] = struct.pack("<I", 20_000)
    path = tmp_path / "big.tiff"
    path.write_bytes(bytes(data))
    with pytest.raises(ImageError, match=r"TIFF image.*20000x20000 px.*pixel limit"):
        read_image(path)


def test_a_truncated_png_is_one_line_quoting_the_codec(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cut.png"
    path.write_bytes(png_header(100, 100))
    with pytest.raises(ImageError, match=r"cut.png.*libpng error"):
        read_image(path)
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # the codec's own line was taken, not printed


def test_not_an_image_is_one_image_error(tmp_path: Path,
                                         capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "text.png"
    path.write_text("hello")
    with pytest.raises(ImageError, match="not a PNG, JPEG, TIFF, BMP, WebP or PNM image"):
        read_image(path)
    assert capfd.readouterr() == ("", "")


@pytest.mark.parametrize("dtype", ["int8", "int16", "int32", "uint32"])
def test_tiffs_of_integer_types_other_than_uint8_16_are_refused(dtype: str,
                                                                tmp_path: Path) -> None:
    ok, buf = cv2.imencode(".tiff", np.full((40, 50, 3), 7, dtype))
    assert ok
    (tmp_path / "x.tiff").write_bytes(buf.tobytes())
    with pytest.raises(ImageError, match=f"x.tiff.*{dtype}"):
        read_image(tmp_path / "x.tiff")


@pytest.mark.parametrize(("dtype", "value", "expected"),
                         [("float64", 0.5, 128), ("float32", 200.0, 200), ("uint16", 51400, 200)])
def test_float_and_16_bit_tiffs_are_scaled_to_8_bits(dtype: str, value: float, expected: int,
                                                     tmp_path: Path) -> None:
    bgr = np.zeros((40, 50, 3), dtype)
    bgr[..., 2] = value  # red in OpenCV's BGR order
    ok, buf = cv2.imencode(".tiff", bgr)
    assert ok
    (tmp_path / "x.tiff").write_bytes(buf.tobytes())
    rgb = read_image(tmp_path / "x.tiff")
    assert rgb.dtype == np.uint8 and rgb.shape == (40, 50, 3)
    assert rgb[0, 0, 0] == expected and rgb[0, 0, 2] == 0


def test_overlay_of_a_16_bit_image_is_scaled_not_wrapped() -> None:
    image = np.full((40, 50), 65000, np.uint16)  # 252 on 8 bits; a cast would wrap to 232
    image[1, 1] = 300  # 1 on 8 bits; a cast would give 44
    out = draw_overlay(image, Detection(reason="test"), None)[:80:2, :100:2]  # drawn at 2x
    assert out.dtype == np.uint8 and out.shape == (40, 50, 3)
    assert out[1, 1].tolist() == [1, 1, 1] and out[5, 5].tolist() == [252, 252, 252]


def test_overlay_of_a_float_image_in_0_1_is_scaled() -> None:
    out = draw_overlay(np.full((40, 50, 3), 0.5), Detection(reason="test"), None)
    assert out[3, 3].tolist() == [128, 128, 128]


@pytest.mark.parametrize(("name", "message"), [("out.xyz", "names no image format"),
                                               ("noext", "no file extension")])
def test_writing_an_unknown_format_names_the_file(name: str, message: str,
                                                  tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=f"{name}.*{message}"):
        write_image(tmp_path / name, np.zeros((8, 8, 3), np.uint8), order="rgb")
    assert list(tmp_path.iterdir()) == []


def test_writing_over_a_directory_or_a_device_is_refused(tmp_path: Path) -> None:
    (tmp_path / "d.png").mkdir()
    with pytest.raises(OutputError, match=r"d.png.*directory"):
        write_image(tmp_path / "d.png", np.zeros((8, 8), np.uint8), order="rgb")
    if os.path.exists("/dev/full"):
        with pytest.raises(OutputError, match=r"/dev/full.*not a regular file"):
            write_text("/dev/full", "x")
        assert os.path.exists("/dev/full") and not os.path.isfile("/dev/full")


def test_a_failed_write_leaves_neither_the_file_nor_a_temporary(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "kept.json").write_text("old")

    def full_disk(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(OutputError, match=r"new.json.*No space left"):
        write_text(tmp_path / "new.json", "{}")
    with pytest.raises(OutputError, match=r"kept.json"):
        write_text(tmp_path / "kept.json", "new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.json"]
    assert (tmp_path / "kept.json").read_text() == "old"


def test_written_images_read_back_with_their_colours(tmp_path: Path) -> None:
    rgb = np.zeros((16, 24, 3), np.uint8)
    rgb[..., 0] = 250
    path = os.fsdecode(os.path.join(os.fsencode(tmp_path), b"out\xff.png"))
    write_image(path, rgb, order="rgb")
    assert np.array_equal(read_image(path), rgb)


@pytest.mark.parametrize("ext", [".png", ".jpg", ".tiff", ".bmp", ".webp", ".ppm", ".pgm"])
def test_headers_of_every_read_format_give_their_size(ext: str) -> None:
    from stackpick_sim.image_header import image_header

    grey = ext == ".pgm"
    ok, buf = cv2.imencode(ext, np.zeros((37, 53) if grey else (37, 53, 3), np.uint8))
    assert ok
    header = image_header(buf.tobytes())
    assert header is not None and header[1:] == (53, 37)
