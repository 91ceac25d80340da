"""The format and declared size of an image file, read from its header alone.

:func:`image_header` recognises PNG, JPEG, TIFF, BMP, WebP and the PNM family (PBM, PGM,
PPM) and returns ``(format, width, height)`` without decoding, so that a file declaring a
huge image is refused before any memory is allocated for it. Other formats (and headers
too short or malformed to give a size) return None: :mod:`stackpick_sim.image_io` refuses
them.
"""

from __future__ import annotations

import re
import struct

Header = tuple[str, int, int]

# JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic); not DHT/JPG/DAC.
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
_TIFF_WIDTH, _TIFF_LENGTH = 256, 257
_TIFF_TYPES = {3: "H", 4: "I", 16: "Q"}  # SHORT, LONG, LONG8 (BigTIFF)
_PNM = re.compile(rb"P[1-6](?:\s+|#[^\n]*\n)+(\d+)(?:\s+|#[^\n]*\n)+(\d+)")


def _png(data: bytes) -> Header | None:
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR" or len(data) < 24:
        return None
    w, h = struct.unpack(">II", data[16:24])
    return "PNG", w, h


def _jpeg(data: bytes) -> Header | None:
    """From the first start-of-frame segment."""
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _JPEG_SOF:
            h, w = struct.unpack(">HH", data[i + 5:i + 9])
            return "JPEG", w, h
        i += 2 + struct.unpack(">H", data[i + 2:i + 4])[0]
    return None


def _tiff(data: bytes) -> Header | None:
    """From the first image file directory (the page OpenCV decodes)."""
    order = {b"II": "<", b"MM": ">"}.get(data[:2])
    if order is None or len(data) < 16:
        return None
    magic = struct.unpack(order + "H", data[2:4])[0]
    if magic not in (42, 43):
        return None
    big = magic == 43
    count_fmt, entry_size = ("Q", 20) if big else ("H", 12)
    ifd = struct.unpack(order + ("Q" if big else "I"), data[8:16] if big else data[4:8])[0]
    count_size = struct.calcsize(count_fmt)
    if ifd + count_size > len(data):
        return None
    n = struct.unpack(order + count_fmt, data[ifd:ifd + count_size])[0]
    size: dict[int, int] = {}
    for k in range(min(n, 4096)):
        entry = ifd + count_size + k * entry_size
        if entry + entry_size > len(data):
            break
        tag, kind = struct.unpack(order + "HH", data[entry:entry + 4])
        fmt = _TIFF_TYPES.get(kind)
        if tag in (_TIFF_WIDTH, _TIFF_LENGTH) and fmt is not None:
            at = entry + (12 if big else 8)
            size[tag] = struct.unpack(order + fmt, data[at:at + struct.calcsize(fmt)])[0]
    if len(size) < 2:
        return None
    return "TIFF", size[_TIFF_WIDTH], size[_TIFF_LENGTH]


def _bmp(data: bytes) -> Header | None:
    if data[:2] != b"BM" or len(data) < 26:
        return None
    if struct.unpack("<I", data[14:18])[0] == 12:  # OS/2 core header: 16-bit sizes
        w, h = struct.unpack("<HH", data[18:22])
    else:
        w, h = struct.unpack("<ii", data[18:26])
    return "BMP", abs(w), abs(h)


def _webp(data: bytes) -> Header | None:
    if data[:4] != b"RIFF" or data[8:12] != b"WEBP" or len(data) < 30:
        return None
    kind = data[12:16]
    if kind == b"VP8 ":
        w, h = struct.unpack("<HH", data[26:30])
        return "WebP", w & 0x3FFF, h & 0x3FFF
    if kind == b"VP8L":
        bits = int.from_bytes(data[21:25], "little")
        return "WebP", (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    if kind == b"VP8X":
        return ("WebP", int.from_bytes(data[24:27], "little") + 1,
                int.from_bytes(data[27:30], "little") + 1)
    return None


def _pnm(data: bytes) -> Header | None:
    match = _PNM.match(data[:1024])
    if match is None:
        return None
    return "PNM", int(match.group(1)), int(match.group(2))


def image_header(data: bytes) -> Header | None:
    """``(format, width, height)`` an image file's header declares, or None if the format is
    not one of PNG, JPEG, TIFF, BMP, WebP, PNM or its header gives no size."""
    for parse in (_png, _jpeg, _tiff, _bmp, _webp, _pnm):
        try:
            found = parse(data)
        except struct.error:  # a header cut short
            found = None
        if found is not None:
            return found
    return None
