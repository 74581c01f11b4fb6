"""Images in and out through OpenImageIO: linear EXR, sRGB PNG previews.

Arrays are (H, W, C) with row 0 at the top of the image. EXR holds linear float32;
PNG, JPEG and other 8-bit formats get the sRGB transfer curve after clamping to [0, 1].
`tonemap` turns linear radiance into such a [0, 1] preview (automatic exposure, filmic curve).
Every write goes to a temporary file in the target's folder and is renamed into place, so a
killed run leaves either the previous file or the new one, never half of one.
"""
import os

import numpy as np

from .errors import SceneError, TracerError

_FLOAT_EXTS = (".exr", ".hdr", ".pfm", ".tif", ".tiff")
# Automatic exposure maps the log-average luminance (Reinhard et al. 2002's "key") to 0.13, which
# the filmic curve shows as 0.18, middle grey (0.46 after the sRGB curve).
KEY = 0.13
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def srgb_encode(linear):
    """Linear [0,1] -> sRGB-encoded [0,1] (IEC 61966-2-1 piecewise curve)."""
    x = np.clip(np.nan_to_num(linear, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


_ROWS = 64  # rows per band where a whole image would need float64 temporaries
EXPOSURE_BLOCKS = 32  # auto_exposure averages blocks of 1/32 of the image's shorter side


def auto_exposure(linear):
    """Scale that maps the log-average luminance of the image's lit blocks to KEY (middle grey
    after `filmic`).

    The luminance is first averaged over square blocks (1/EXPOSURE_BLOCKS of the shorter side, at
    least one pixel; the rows and columns past the last whole block are left out): a block mean
    of a Monte Carlo image is nearly free of its noise, so renders of one scene by methods with
    different noise (a sampler that leaves many pixels black and others bright, say) get the same
    exposure, where a log-average over pixels would darken the noisier one. Black blocks
    (background, no sample) are left out, so that an object against black does not set the
    exposure, and so are non-finite pixels (counted as black); 1.0 when nothing is lit."""
    a = np.asarray(linear, dtype=np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    lum = a[..., :3] @ _LUMA[: a.shape[-1]] if a.shape[-1] >= 3 else a[..., 0]
    lum = np.where(np.isfinite(lum), lum, 0.0)
    b = max(1, min(lum.shape) // EXPOSURE_BLOCKS)
    h, w = lum.shape[0] // b * b, lum.shape[1] // b * b
    blocks = lum[:h, :w].reshape(h // b, b, w // b, b).mean(axis=(1, 3))
    blocks = blocks[blocks > 0.0]
    if blocks.size == 0:
        return 1.0
    return float(KEY / np.exp(np.mean(np.log(blocks))))


def filmic(x):
    """The ACES filmic curve (Narkowicz 2015 fit), clamped to [0, 1]: 0 -> 0, monotone, slope 0.21
    at 0 and 1 from x = 7.24 on. Input: exposed linear radiance; output: display-linear [0, 1]."""
    x = np.clip(np.nan_to_num(np.asarray(x, dtype=np.float64), nan=0.0, posinf=1e30, neginf=0.0), 0.0, 1e30)
    y = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
    return np.clip(np.nan_to_num(y, nan=1.0), 0.0, 1.0)


def tonemap(linear, exposure=0.0, auto=True):
    """Linear radiance (H, W, C) -> display-linear values in [0, 1] for an 8-bit preview (write_image
    applies the sRGB curve). The radiance is scaled by 2^exposure times, if `auto`, the automatic
    exposure (auto_exposure: log-average luminance to middle grey), then goes through `filmic` per channel.
    NaN and -inf give 0, +inf gives 1."""
    scale = 2.0 ** float(exposure) * (auto_exposure(linear) if auto else 1.0)
    return filmic(np.asarray(linear, dtype=np.float64) * scale)


def preview(linear, stops):
    """tonemap(linear, stops, auto=False) as float32, computed in bands of rows (its float64
    temporaries stay small on a large image): what write_outputs turns into the PNG."""
    a = np.asarray(linear)
    out = np.empty(a.shape, np.float32)
    for r in range(0, a.shape[0], _ROWS):
        out[r:r + _ROWS] = tonemap(a[r:r + _ROWS], stops, auto=False)
    return out


def _one_line(text, default):
    """An OpenImageIO error message (often several lines, repeated) as one line."""
    lines = [line.strip() for line in str(text or "").splitlines() if line.strip()]
    return lines[0] if lines else default


def temp_path(path):
    """A temporary name in the folder of `path` that keeps its extension (image writers pick the
    format from it): `dir/.name.tmp-<pid>.ext`."""
    folder, name = os.path.split(os.fspath(path))
    stem, ext = os.path.splitext(name)
    return os.path.join(folder, f".{stem}.tmp-{os.getpid()}{ext}")


def replace_atomically(path, write):
    """Call write(tmp) to write the whole file to a temporary name beside `path`, then rename it
    into place (os.replace); on any failure the temporary file is removed and `path` is untouched."""
    tmp = temp_path(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as e:
        raise TracerError(f"{path}: cannot write output ({e.strerror or e})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_image(path, array, channel_names=None):
    """Write an (H, W) or (H, W, C) array to `path` (C <= 4 for 8-bit formats).

    The format follows the extension: `.exr` (and other float formats) get linear float32,
    anything else 8-bit sRGB of the values clamped to [0, 1] (pass `tonemap(image)` for a preview
    of radiance). The file is written under a temporary name and renamed into place. Raises
    TracerError naming the path if it cannot be written.
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
        pixels = np.empty((h, w, c), np.uint8)
        for r in range(0, h, _ROWS):  # in bands of rows: the float64 temporaries stay small
            pixels[r:r + _ROWS] = np.round(srgb_encode(a[r:r + _ROWS]) * 255.0)
    if channel_names is not None:
        spec.channelnames = tuple(channel_names)

    def write(tmp):
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise TracerError(f"{path}: cannot write output ({_one_line(oiio.geterror(), 'unknown image format')})")
        try:
            if not out.open(tmp, spec) or not out.write_image(pixels):
                raise TracerError(f"{path}: cannot write output ({_one_line(out.geterror(), 'unknown error')})")
        finally:
            out.close()

    replace_atomically(path, write)


def read_image(path, what="image"):
    """Read an image as float32 (H, W, C). Raises SceneError naming the file on failure
    (missing, not an image, truncated)."""
    import OpenImageIO as oiio

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: {what} not found")
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise SceneError(f"{path}: cannot read {what} ({_one_line(oiio.geterror(), 'not an image')})")
    try:
        data = inp.read_image(format="float")
        error = inp.geterror()  # also clears it, so that OpenImageIO does not print it at exit
    finally:
        inp.close()
    if data is None or error:
        raise SceneError(f"{path}: cannot read {what} ({_one_line(error, 'truncated or corrupt')})")
    data = np.asarray(data, dtype=np.float32)
    if data.ndim == 2:
        data = data[:, :, None]
    return data
