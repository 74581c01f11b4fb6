"""Images in and out through OpenImageIO: linear EXR, sRGB PNG previews.

Arrays are (H, W, C) with row 0 at the top of the image. EXR holds linear float32;
PNG, JPEG and other 8-bit formats get the sRGB transfer curve after clamping to [0, 1].
"""
import os

import numpy as np

from .errors import SceneError, TracerError

_FLOAT_EXTS = (".exr", ".hdr", ".pfm", ".tif", ".tiff")


def srgb_encode(linear):
    """Linear [0,1] -> sRGB-encoded [0,1] (IEC 61966-2-1 piecewise curve)."""
    x = np.clip(np.nan_to_num(linear, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def write_image(path, array, channel_names=None):
    """Write an (H, W) or (H, W, C) array to `path` (C <= 4 for 8-bit formats).

    The format follows the extension: `.exr` (and other float formats) get linear float32,
    anything else 8-bit sRGB. Raises TracerError naming the path if it cannot be written.
    """
    import OpenImageIO as oiio

    path = os.fspath(path)
    a = np.asarray(array, dtype=np.float32)
    if a.ndim == 2:
        a = a[:, :, None]
    ext = os.path.splitext(path)[1].lower()
    if a.ndim != 3 or (ext not in _FLOAT_EXTS and a.shape[2] not in (1, 2, 3, 4)):
        raise TracerError(f"{path}: cannot write an array of shape {np.shape(array)} as an image")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise TracerError(f"{path}: cannot write output, folder {folder} does not exist")
    h, w, c = a.shape
    if ext in _FLOAT_EXTS:
        spec = oiio.ImageSpec(w, h, c, "float")
        pixels = np.ascontiguousarray(a)
    else:
        spec = oiio.ImageSpec(w, h, c, "uint8")
        pixels = np.ascontiguousarray(np.round(srgb_encode(a) * 255.0).astype(np.uint8))
    if channel_names is not None:
        spec.channelnames = tuple(channel_names)
    out = oiio.ImageOutput.create(path)
    if out is None:
        raise TracerError(f"{path}: cannot write output ({oiio.geterror() or 'unknown image format'})")
    try:
        if not out.open(path, spec):
            raise TracerError(f"{path}: cannot write output ({out.geterror()})")
        if not out.write_image(pixels):
            raise TracerError(f"{path}: cannot write output ({out.geterror()})")
    finally:
        out.close()


def read_image(path, what="image"):
    """Read an image as float32 (H, W, C). Raises SceneError naming the file on failure."""
    import OpenImageIO as oiio

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: {what} not found")
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise SceneError(f"{path}: cannot read {what} ({oiio.geterror()})")
    try:
        data = inp.read_image(format="float")
    finally:
        inp.close()
    if data is None:
        raise SceneError(f"{path}: cannot read {what}")
    data = np.asarray(data, dtype=np.float32)
    if data.ndim == 2:
        data = data[:, :, None]
    return data
