"""Reading and writing image files safely.

:func:`read_image` reads the bytes itself (any path the OS accepts, also one that is not
UTF-8), refuses what is not a regular file before opening it (a FIFO would block), refuses a
file larger than :data:`MAX_FILE_BYTES`, a format other than those of :data:`READ_FORMATS`
or an image whose header declares more than :data:`MAX_IMAGE_PIXELS` before anything is
decoded (:mod:`stackpick_sim.image_header`), and decodes with OpenCV with the
codecs' own messages captured: every problem is one
:class:`~stackpick_sim.exceptions.ImageError` that names the file and quotes the codec's
reason. :func:`write_image` encodes in memory and writes through
:func:`stackpick_sim.files.write_bytes` (atomic, checked).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ImageError, OutputError
from stackpick_sim.files import shown, write_bytes
from stackpick_sim.image_header import image_header
from stackpick_sim.liboutput import captured_stderr
from stackpick_sim.vision.edges import as_rgb_or_gray

#: The most pixels an image file may declare: a 4096 x 4096 frame, the largest camera a
#: scene configures (``camera.width``/``camera.height``); the detector refuses more too.
MAX_IMAGE_PIXELS = 4096 * 4096
#: The largest image file read, bytes: an uncompressed 16-bit RGBA image of
#: MAX_IMAGE_PIXELS (8 bytes a pixel) plus 1 MiB of metadata. Float TIFFs of the largest
#: size exceed it and are refused.
MAX_FILE_BYTES = 8 * MAX_IMAGE_PIXELS + (1 << 20)
#: The formats read_image accepts (those whose header image_header reads).
READ_FORMATS = "PNG, JPEG, TIFF, BMP, WebP or PNM"



def _read_bytes(path: str | os.PathLike[str]) -> bytes:
    """The bytes of a regular file of at most MAX_FILE_BYTES; ImageError otherwise."""
    name = shown(path)
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise ImageError(f"cannot read image '{name}': {kind}")
        if info.st_size > MAX_FILE_BYTES:
            raise ImageError(f"image file '{name}' has {info.st_size} bytes, more than the "
                             f"{MAX_FILE_BYTES} byte limit")
        # O_NONBLOCK: a file swapped for a FIFO since the stat cannot block the open.
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                raise ImageError(f"cannot read image '{name}': not a regular file")
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ImageError(f"cannot read image '{name}': {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        raise ImageError(f"image file '{name}' is larger than the {MAX_FILE_BYTES} byte limit")
    return data


def decode_image(data: bytes, name: str = "<bytes>") -> NDArray:
    """Decode image file bytes as OpenCV stores them ((H, W) or (H, W, C) BGR[A], the file's
    dtype); ImageError naming ``name`` if the bytes are not an image of at most
    MAX_IMAGE_PIXELS."""
    header = image_header(data)
    if header is None:
        raise ImageError(f"cannot read image '{name}': not a {READ_FORMATS} image, or its "
                         "header is damaged")
    kind, w, h = header
    if w * h > MAX_IMAGE_PIXELS:
        raise ImageError(f"{kind} image '{name}' declares {w}x{h} px, more than the "
                         f"{MAX_IMAGE_PIXELS} pixel limit (4096 x 4096)")
    with captured_stderr() as said:
        try:
            img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
            failure = None
        except cv2.error as exc:
            img, failure = None, str(exc)
    if failure is not None and "CV_IO_MAX_IMAGE_PIXELS" in failure:
        raise ImageError(f"image '{name}' declares more than the {MAX_IMAGE_PIXELS} pixel "
                         "limit (4096 x 4096)")
    if img is None or img.size == 0:
        reason = said[-1] if said else "the codec found no image in it"
        raise ImageError(f"cannot decode image '{name}': {reason}")
    return np.asarray(img)


def _bgr_to_rgb(img: NDArray, name: str) -> NDArray:
    if img.ndim == 2:
        return img
    channels = img.shape[2]
    if channels == 1:
        return img[:, :, 0]
    if channels in (3, 4):
        return img[:, :, 2::-1]  # BGR(A) -> RGB, any dtype
    raise ImageError(f"image '{name}' has {channels} channels; allowed: 1 (grey), 3 (colour) "
                     "or 4 (colour and alpha)")


def read_image(path: str | os.PathLike[str]) -> NDArray[np.uint8]:
    """An image file as (H, W) grey or (H, W, 3) RGB uint8.

    16-bit images are scaled by 1/257, float images in [0, 1] by 255 (else clipped to
    [0, 255]); alpha is dropped. Other sample types (signed or 32-bit integers) and
    non-finite floats are refused. Raises ImageError naming the file for anything unusable.
    """
    name = shown(path)
    img = _bgr_to_rgb(decode_image(_read_bytes(path), name), name)
    try:
        return as_rgb_or_gray(img)
    except ImageError as exc:
        raise ImageError(f"image '{name}': {exc}") from None


#: File extensions :func:`write_image` accepts.
WRITE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


def encode_image(image: NDArray, ext: str, order: Literal["rgb", "bgr"]) -> bytes:
    """Encode an (H, W) or (H, W, 3) uint8 image in the format of extension ``ext``."""
    if ext.lower() not in WRITE_EXTENSIONS:
        given = f"extension {ext!r} names no image format" if ext else "no file extension"
        raise OutputError(f"{given}; use one of {', '.join(WRITE_EXTENSIONS)}")
    img = as_rgb_or_gray(image)
    if img.ndim == 3 and order == "rgb":
        img = np.ascontiguousarray(img[:, :, ::-1])
    with captured_stderr() as said:
        try:
            ok, buf = cv2.imencode(ext.lower(), img)
        except cv2.error as exc:
            ok, buf = False, None
            said.append(str(exc).strip().splitlines()[-1])
    if not ok or buf is None:
        raise OutputError(f"cannot encode a {ext} image: {said[-1] if said else 'unknown error'}")
    return bytes(buf)


def write_image(path: str | os.PathLike[str], image: NDArray,
                order: Literal["rgb", "bgr"]) -> None:
    """Write an (H, W) grey or (H, W, 3) image whose channels are in ``order`` to ``path``,
    in the format its extension names, atomically; OutputError naming the file on failure."""
    try:
        data = encode_image(image, Path(path).suffix, order)
    except (OutputError, ImageError) as exc:
        raise OutputError(f"cannot write '{shown(path)}': {exc}") from None
    write_bytes(path, data)
