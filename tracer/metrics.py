"""Error metrics of an image I against a reference R, both (H, W, 3) linear radiance.

relMSE     mean over pixels and channels of (I - R)^2 / (R^2 + 0.01)
MSE        mean of (I - R)^2
MrSE       trimmed mean relative squared error: per pixel (I - R)^2 / (R^2 + 0.01), averaged
           over channels, with the largest 0.01% of pixels dropped (fireflies do not dominate)
1-SSIM     1 minus the structural similarity (scikit-image) of the two images after
           clamping to [0, 1] with the sRGB curve, over the three channels
"""
import numpy as np

from .errors import TracerError


def _pair(image, reference):
    i = np.asarray(image, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if i.ndim == 2:
        i = i[:, :, None]
    if r.ndim == 2:
        r = r[:, :, None]
    if i.shape[:2] != r.shape[:2]:
        raise TracerError(f"image is {i.shape[1]}x{i.shape[0]} but the reference is {r.shape[1]}x{r.shape[0]}")
    c = min(i.shape[2], r.shape[2], 3)
    return i[:, :, :c], r[:, :, :c]


def relmse(image, reference, eps=0.01):
    i, r = _pair(image, reference)
    return float(np.mean((i - r) ** 2 / (r * r + eps)))


def mse(image, reference):
    i, r = _pair(image, reference)
    return float(np.mean((i - r) ** 2))


def mrse_trimmed(image, reference, trim=1e-4, eps=0.01):
    i, r = _pair(image, reference)
    e = np.sort(((i - r) ** 2 / (r * r + eps)).mean(axis=2).ravel())
    keep = e.size - int(np.floor(trim * e.size))
    return float(e[:max(keep, 1)].mean())


def one_minus_ssim(image, reference):
    from skimage.metrics import structural_similarity

    from .imageio import srgb_encode

    i, r = _pair(image, reference)
    i, r = srgb_encode(i), srgb_encode(r)
    side = min(i.shape[0], i.shape[1])
    win = min(7, side if side % 2 == 1 else side - 1)
    if win < 3:
        raise TracerError("images are too small for SSIM (need at least 3x3)")
    s = structural_similarity(i, r, channel_axis=2, data_range=1.0, win_size=win)
    return float(1.0 - s)


METRICS = {"relMSE": relmse, "MSE": mse, "MrSE": mrse_trimmed, "1-SSIM": one_minus_ssim}


def all_metrics(image, reference):
    """{name: value} for every metric in METRICS."""
    return {name: f(image, reference) for name, f in METRICS.items()}
