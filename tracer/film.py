"""The film: per-pixel sums in float64, from which the mean and its variance follow.

With the box filter each sample lands in its own pixel. The film keeps, per pixel,
the sample count n, the sum and the sum of squares of the radiance samples (RGB), and
sums of the AOVs (albedo, shading normal, depth at the first hit). Samples are added in
sample-index order, so the float64 sums, and the image, do not depend on wave size or
thread count.
"""
import numpy as np

from ._jit import jit

AOV_NAMES = ("albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z")
N_AOV = len(AOV_NAMES)


class Film:
    """Accumulates radiance samples and AOVs for a width x height image."""

    def __init__(self, width, height):
        self.width = int(width)
        self.height = int(height)
        n = self.width * self.height
        self.count = np.zeros(n, dtype=np.float64)  # samples per pixel
        self.sum = np.zeros((n, 3), dtype=np.float64)
        self.sumsq = np.zeros((n, 3), dtype=np.float64)
        self.aov = np.zeros((n, N_AOV), dtype=np.float64)

    @property
    def n_pixels(self):
        return self.width * self.height

    def add(self, pixel, radiance, aov):
        """Add samples: pixel (n,) int64, radiance (n,3) float64, aov (n, N_AOV) float64, in order."""
        _accumulate(self.count, self.sum, self.sumsq, self.aov, pixel, radiance, aov)

    def mean(self):
        """(H, W, 3) float64 per-pixel mean (0 where no sample yet)."""
        n = np.maximum(self.count, 1.0)[:, None]
        return (self.sum / n).reshape(self.height, self.width, 3)

    def variance(self):
        """(H, W, 3) float64 variance of the per-pixel mean (sample variance / n)."""
        n = self.count[:, None]
        safe = np.maximum(n, 2.0)
        m = self.sum / np.maximum(n, 1.0)
        var = np.maximum(self.sumsq - n * m * m, 0.0) / (safe - 1.0) / safe
        var = np.where(n >= 2.0, var, 0.0)
        return var.reshape(self.height, self.width, 3)

    def aovs(self):
        """{name: (H, W, k) float32}: albedo, normal, depth (means over samples)."""
        n = np.maximum(self.count, 1.0)[:, None]
        a = (self.aov / n).reshape(self.height, self.width, N_AOV).astype(np.float32)
        return {"albedo": a[:, :, 0:3], "normal": a[:, :, 3:6], "depth": a[:, :, 6:7]}

    def __repr__(self):
        return f"Film({self.width}x{self.height}, {int(self.count.sum())} samples)"


@jit
def _accumulate(count, s, sq, aov, pixel, radiance, aovs):
    # Sequential on purpose: the order of additions into each pixel is the sample order.
    for i in range(pixel.shape[0]):
        p = pixel[i]
        count[p] += 1.0
        for c in range(3):
            r = radiance[i, c]
            s[p, c] += r
            sq[p, c] += r * r
        for c in range(aov.shape[1]):
            aov[p, c] += aovs[i, c]
