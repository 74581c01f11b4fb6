"""Textures: what readers say (TextureSpec) and the one table the kernels read (Textures).

A reader gives each textured material slot a TextureSpec: a bitmap file, a checkerboard of two
colours, or a constant, with an affine UV map (`uvscale`/`uoffset` or a `to_uv` matrix become
its six coefficients). `build_textures` reads every bitmap once through OpenImageIO (8- and
16-bit images are decoded from sRGB, float images are taken as linear), stores all texels in one
float32 array, and returns the Textures whose rows tracer.material documents. A bitmap that
cannot be read is a warning naming the file, and the texture becomes the spec's fallback colour.
"""
import logging
import os
from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError
from .material import TEX_BITMAP, TEX_CHECKER, TEX_CONSTANT, TEX_INFO_COLS

IDENTITY_UV = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


@dataclass
class TextureSpec:
    """One texture as a reader gives it. kind "bitmap" (path), "checker" (color0, color1) or
    "constant" (color0); uv: (a, b, c, d, e, f), (u, v) -> (a u + b v + c, d u + e v + f);
    fallback: the colour used if the bitmap cannot be read; where: the file (and line) that
    named it, for messages."""

    kind: str
    path: str = ""
    color0: tuple = (0.5, 0.5, 0.5)
    color1: tuple = (0.5, 0.5, 0.5)
    uv: tuple = IDENTITY_UV
    fallback: tuple = (0.5, 0.5, 0.5)
    where: str = ""
    gamma: float = 0.0  # 8/16-bit decoding: 0 (or -1) sRGB, g > 0 the power law v^g (1: linear)


@dataclass
class Textures:
    """Every texture of a scene: info (T, 16) float64 rows (tracer.material), data the texels of
    all bitmaps as one float32 array (linear RGB), names one label per row."""

    info: np.ndarray = field(default_factory=lambda: np.zeros((0, TEX_INFO_COLS)))
    data: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    names: list = field(default_factory=list)

    @property
    def nbytes(self):
        return int(self.info.nbytes + self.data.nbytes)

    def __len__(self):
        return self.info.shape[0]

    def mean(self, k):
        """Mean RGB of texture k over its texels (a checkerboard: of its two colours)."""
        row = self.info[k]
        if row[0] == TEX_CHECKER:
            return 0.5 * (row[10:13] + row[13:16])
        if row[0] == TEX_BITMAP:
            o, w, h = (int(v) for v in row[1:4])
            return self.data[o:o + w * h * 3].reshape(-1, 3).mean(axis=0, dtype=np.float64)
        return row[10:13].copy()


def srgb_decode(x, dtype=np.float32):
    """sRGB-encoded [0, 1] -> linear (IEC 61966-2-1), as `dtype`."""
    x = np.asarray(x, dtype=dtype)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(dtype)


def read_texture(path, gamma=0.0, what="texture"):
    """(H, W, 3) float32 linear RGB of an image file: 8/16-bit formats decoded from sRGB (gamma 0
    or -1) or by the power law v^gamma (gamma > 0; 1: stored linear, as Mitsuba's `gamma` and
    `raw` say), float formats as they are; grey images repeated to RGB, alpha dropped. Raises
    SceneError naming the file (and `what` it is)."""
    import OpenImageIO as oiio

    from .imageio import read_image

    img = read_image(path, what=what)
    inp = oiio.ImageInput.open(path)
    integer = True
    if inp is not None:
        integer = inp.spec().format.basetype in (oiio.UINT8, oiio.UINT16, oiio.INT8, oiio.INT16)
        inp.close()
    c = img.shape[2]
    rgb = np.repeat(img[:, :, :1], 3, axis=2) if c < 3 else img[:, :, :3]
    if not np.all(np.isfinite(rgb)):
        raise SceneError(f"{path}: {what} holds non-finite values")
    if integer and gamma > 0.0:
        return np.ascontiguousarray(np.power(np.clip(rgb, 0.0, None), gamma), dtype=np.float32)
    return srgb_decode(rgb) if integer else np.ascontiguousarray(rgb, dtype=np.float32)


def build_textures(specs, warnings):
    """Textures of a list of TextureSpecs (row k is specs[k]); each file is read once."""
    from .readers.text import warn

    info = np.zeros((len(specs), TEX_INFO_COLS))
    chunks, cache, names = [], {}, []
    offset = 0
    for k, sp in enumerate(specs):
        info[k, 4:10] = sp.uv
        info[k, 10:13] = sp.color0
        info[k, 13:16] = sp.color1
        names.append(os.path.basename(sp.path) if sp.kind == "bitmap" else sp.kind)
        if sp.kind == "checker":
            info[k, 0] = TEX_CHECKER
            continue
        if sp.kind != "bitmap":
            info[k, 0] = TEX_CONSTANT
            continue
        key = (sp.path, sp.gamma if sp.gamma > 0.0 else 0.0)
        if key not in cache:
            try:
                img = read_texture(sp.path, sp.gamma)
            except SceneError as e:
                warn(warnings, f"{sp.where}: {e}; using the constant {_fmt(sp.fallback)} instead", logging.WARNING)
                cache[key] = None
            else:
                cache[key] = (offset, img.shape[1], img.shape[0])
                chunks.append(img.reshape(-1))
                offset += img.size
        got = cache[key]
        if got is None:
            info[k, 0] = TEX_CONSTANT
            info[k, 10:13] = sp.fallback
        else:
            info[k, 0] = TEX_BITMAP
            info[k, 1:4] = got
    data = np.concatenate(chunks) if chunks else np.zeros(3, np.float32)
    return Textures(info, np.ascontiguousarray(data, dtype=np.float32), names)


def _fmt(c):
    return "(" + ", ".join(f"{v:.3g}" for v in c) + ")"
