"""The camera's sensor: vignetting, photon and read noise with a gain, quantisation, JPEG.

The rendered image is taken as the mean signal: grey level ``g`` (0-255) at gain 1 means
``g / 255 * full_well`` electrons. At gain ``G`` the same grey level is reached with ``G``
times fewer electrons, so photon (Poisson) noise grows relative to the signal; read noise
(Gaussian, electrons rms) is added before the gain. The result is quantised to 8 bits and,
optionally, JPEG-compressed (Foi et al. 2008, "Practical Poissonian-Gaussian noise modeling",
for the noise model).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import CameraCfg

#: Mean electron counts below which photon noise is drawn from the Poisson law itself.
POISSON_EXACT_BELOW = 50.0


@lru_cache(maxsize=8)
def _vignette(height: int, width: int, strength: float) -> NDArray[np.float32]:
    """(H, W, 1) brightness factor: 1 at the centre, ``1 - strength`` in the corners."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float32)
    r2 = ((u - (width - 1) / 2) ** 2 + (v - (height - 1) / 2) ** 2) / (
        ((width - 1) / 2) ** 2 + ((height - 1) / 2) ** 2)
    return (1.0 - np.float32(strength) * r2)[..., None]


def vignette(image: NDArray[np.float32], strength: float) -> NDArray[np.float32]:
    """``image`` (H, W, C) darkened radially by ``strength`` at the corners."""
    if strength <= 0:
        return image
    return image * _vignette(image.shape[0], image.shape[1], float(strength))


def expose(image: NDArray[np.float32], cam: CameraCfg,
           rng: np.random.Generator) -> NDArray[np.float32]:
    """Photon and read noise with gain on a mean image (grey levels), unclipped (see module)."""
    per_grey = cam.full_well / 255.0 / cam.gain  # electrons per grey level at this gain
    electrons = np.clip(image, 0.0, None) * np.float32(per_grey)
    # Above POISSON_EXACT_BELOW electrons the photon count is drawn from the normal law of
    # the Poisson law's mean and variance (its skew is then below 0.15); with the read noise,
    # also normal and independent, that is one normal draw of the summed variance.
    read_var = np.float32(cam.read_noise**2)
    noise = rng.standard_normal(image.shape, dtype=np.float32)
    counted = electrons + np.sqrt(electrons + read_var) * noise
    dim = electrons < POISSON_EXACT_BELOW
    if dim.any():
        # Poisson counts themselves, the read noise added from the same normal draws.
        counted[dim] = (rng.poisson(electrons[dim]).astype(np.float32)
                        + np.float32(cam.read_noise) * noise[dim])
    return counted / np.float32(per_grey)


def quantise(image: NDArray[np.float32]) -> NDArray[np.uint8]:
    """Round to 8-bit grey levels, clipped at 0 and 255 (saturation)."""
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def jpeg(image: NDArray[np.uint8], quality: int) -> NDArray[np.uint8]:
    """``image`` (RGB) through JPEG compression at ``quality`` (1-100); 0: unchanged."""
    if quality <= 0:
        return image
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV failed to JPEG-encode a frame")  # a bug, not bad input
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if decoded is None:
        raise RuntimeError("OpenCV failed to decode its own JPEG")  # a bug, not bad input
    return np.asarray(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB), dtype=np.uint8)
