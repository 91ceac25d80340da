"""How object kinds and the belt look: meshes with texture coordinates and seeded textures.

MuJoCo's primitives cannot carry a 2D picture on a cylinder's cap, so caps that show more
than one flat colour get a visual-only *decal*: a flat disc or ring mesh with texture
coordinates, 0.2 mm above the cap (never colliding, no mass). A tape roll's hole is a real
hole: its visual is a tube mesh and its collision cylinder is not drawn. Textures are drawn
here from a seeded generator (no files, no downloads):

- ``printed``: the kind's colour with a seeded word, a logo (star and rings) and a stripe;
- ``can``: a tinplate lid: a bright rim, a dark groove and a countersunk panel ring;
- the belt (``conveyor.texture``): dark rubber with lengthwise wear streaks and scuffs.
"""

from __future__ import annotations

import math
import string
import zlib

import cv2
import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import ObjectTypeCfg

#: Height of a decal above the cap it lies on, m (above depth-buffer fighting at 0.3 m).
DECAL_LIFT = 0.0002
#: Segments of a decal's or tube's circle (the cylinders' CYLINDER_SLICES).
MESH_SEGMENTS = 64
#: Side of a generated texture, px.
TEXTURE_PX = 256
#: Belt texture: px per metre along the belt, and the texture's length along it, m.
BELT_TEXTURE_PX_PER_M = 1024
BELT_TEXTURE_PERIOD = 0.25

FloatArray = NDArray[np.float64]


def _ring(radius: float, z: float) -> FloatArray:
    a = 2.0 * math.pi * np.arange(MESH_SEGMENTS) / MESH_SEGMENTS
    return np.column_stack([radius * np.cos(a), radius * np.sin(a), np.full(MESH_SEGMENTS, z)])


def annulus(inner: float, outer: float, z: float,
            up: bool = True) -> tuple[FloatArray, NDArray[np.int32], FloatArray]:
    """(vertices (N, 3), faces (M, 3), uv (N, 2)) of a flat ring (``inner`` 0: a disc) at
    height ``z``, its faces turned up (+z) or down; uv maps the outer circle onto the texture."""
    n = MESH_SEGMENTS
    verts = np.vstack([_ring(max(inner, 1e-5), z), _ring(outer, z)])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, n + i, n + j), (i, n + j, j)]
    tri = np.array(faces, dtype=np.int32)
    if not up:
        tri = tri[:, ::-1]
    uv = 0.5 + 0.5 * verts[:, :2] / outer
    uv[:, 1] = 1.0 - uv[:, 1]  # image rows run down the texture
    return verts, tri, uv


def _wall(radius: float, z0: float, z1: float,
          outward: bool) -> tuple[FloatArray, NDArray[np.int32], FloatArray]:
    n = MESH_SEGMENTS
    verts = np.vstack([_ring(radius, z0), _ring(radius, z1)])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, n + j), (i, n + j, n + i)]
    tri = np.array(faces, dtype=np.int32)
    if not outward:
        tri = tri[:, ::-1]
    uv = np.zeros((2 * n, 2))
    return verts, tri, uv


def tube(inner: float, outer: float,
         height: float) -> tuple[FloatArray, NDArray[np.int32], FloatArray]:
    """A closed tube (a tape roll) centred on the origin along z, with its uv (caps only)."""
    h = height / 2
    parts = [annulus(inner, outer, h), annulus(inner, outer, -h, up=False),
             _wall(outer, -h, h, outward=True), _wall(inner, -h, h, outward=False)]
    verts, faces, uvs, base = [], [], [], 0
    for v, f, uv in parts:
        verts.append(v)
        faces.append(f + base)
        uvs.append(uv)
        base += len(v)
    return np.vstack(verts), np.vstack(faces), np.vstack(uvs)


def add_mesh(spec: mujoco.MjSpec, name: str,
             mesh: tuple[FloatArray, NDArray[np.int32], FloatArray]) -> None:
    """Add a mesh with per-vertex texture coordinates; its inertia is the shell's (a flat
    decal has no volume; visual meshes get no mass anyway)."""
    verts, faces, uv = mesh
    m = spec.add_mesh(name=name)
    m.uservert = verts.ravel().tolist()
    m.userface = faces.ravel().tolist()
    m.usertexcoord = uv.ravel().tolist()
    m.userfacetexcoord = faces.ravel().tolist()
    m.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL


def add_texture(spec: mujoco.MjSpec, name: str, rgb: NDArray[np.uint8]) -> None:
    """Add an (H, W, 3) uint8 RGB picture as a 2D texture (row 0 = v = 0)."""
    tex = spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D,
                           width=int(rgb.shape[1]), height=int(rgb.shape[0]), nchannel=3)
    tex.data = np.ascontiguousarray(rgb, dtype=np.uint8).tobytes()


def kind_rng(type_name: str, kind: ObjectTypeCfg) -> np.random.Generator:
    """The generator of a kind's texture: fixed by its name and ``print_seed``."""
    return np.random.default_rng([zlib.crc32(type_name.encode()), kind.print_seed])


def _rgb255(kind: ObjectTypeCfg) -> tuple[int, int, int]:
    return tuple(round(255 * c) for c in kind.rgba[:3])  # type: ignore[return-value]


def printed_texture(kind: ObjectTypeCfg, rng: np.random.Generator) -> NDArray[np.uint8]:
    """A printed lid: the kind's colour, a seeded word across it, a logo and a stripe."""
    n = TEXTURE_PX
    base = np.array(_rgb255(kind), dtype=np.uint8)
    img = np.empty((n, n, 3), dtype=np.uint8)
    img[:] = base
    ink = tuple(int(c) for c in (255 - base) // 2 + rng.integers(0, 60, 3))
    accent = tuple(int(c) for c in rng.integers(0, 256, 3))
    # A stripe across the lid, a logo above the word.
    y = int(rng.integers(int(0.55 * n), int(0.7 * n)))
    cv2.rectangle(img, (0, y), (n, y + n // 12), accent, thickness=-1)
    cx, cy, r = n // 2, int(0.3 * n), n // 9
    star = [(cx + (r if i % 2 == 0 else r // 2) * math.sin(math.pi * i / 5),
             cy - (r if i % 2 == 0 else r // 2) * math.cos(math.pi * i / 5)) for i in range(10)]
    cv2.fillPoly(img, [np.array(star, dtype=np.int32)], ink, lineType=cv2.LINE_AA)
    cv2.circle(img, (cx, cy), int(1.4 * r), ink, thickness=3, lineType=cv2.LINE_AA)
    letters = "".join(rng.choice(list(string.ascii_uppercase), int(rng.integers(4, 7))))
    (w, h), _ = cv2.getTextSize(letters, cv2.FONT_HERSHEY_DUPLEX, 1.6, 3)
    cv2.putText(img, letters, ((n - w) // 2, int(0.5 * n) + h // 2), cv2.FONT_HERSHEY_DUPLEX,
                1.6, ink, 3, cv2.LINE_AA)
    return img


def can_texture(kind: ObjectTypeCfg) -> NDArray[np.uint8]:
    """A can's lid seen from above: bright rim, dark groove, countersunk panel ring."""
    n = TEXTURE_PX
    metal = np.array(_rgb255(kind), dtype=np.float64)
    img = np.empty((n, n, 3), dtype=np.uint8)
    img[:] = metal.astype(np.uint8)
    c = n // 2
    px_per_m = n / (2 * kind.radius)
    groove = round((kind.radius - kind.rim_width) * px_per_m)
    cv2.circle(img, (c, c), c, tuple(int(x) for x in np.minimum(metal * 1.15, 255)), -1,
               cv2.LINE_AA)
    cv2.circle(img, (c, c), groove, tuple(int(x) for x in metal * 0.45), max(2, n // 64),
               cv2.LINE_AA)
    cv2.circle(img, (c, c), int(groove * 0.82), tuple(int(x) for x in metal * 0.7),
               max(1, n // 128), cv2.LINE_AA)
    return img


def belt_texture(rng: np.random.Generator, width_m: float) -> NDArray[np.uint8]:
    """Dark rubber, wear streaks along the belt (image rows = along the belt) and scuffs."""
    rows = int(BELT_TEXTURE_PERIOD * BELT_TEXTURE_PX_PER_M)
    cols = int(width_m * BELT_TEXTURE_PX_PER_M / 2)
    grain = rng.normal(0.0, 3.0, (rows, cols))
    grain = np.asarray(cv2.GaussianBlur(grain, (0, 0), 1.5), dtype=np.float64)
    streaks = np.asarray(cv2.GaussianBlur(rng.normal(0.0, 8.0, (1, cols)), (0, 0), 2.0),
                         dtype=np.float64)
    img = 52.0 + grain + streaks
    for _ in range(int(rng.integers(6, 12))):  # scuffs: short pale marks along the travel
        r, c = int(rng.integers(0, rows)), int(rng.integers(0, cols))
        length, tone = int(rng.integers(10, 60)), float(rng.uniform(12.0, 30.0))
        cv2.line(img, (c, r), (c + int(rng.integers(-3, 4)), min(rows - 1, r + length)),
                 52.0 + tone, int(rng.integers(1, 4)), cv2.LINE_AA)
    grey = np.clip(img, 0, 255).astype(np.uint8)
    return np.repeat(grey[..., None], 3, axis=2)
