"""What a gradient-domain render accumulates, whatever its shift: the base image, its indirect and
direct parts, and the dx, dy gradient images (GradientFilms), and how a wave's base samples and
gradient samples are added to them (add_gradients)."""
import numba
from numba import prange

from .._jit import jit, kernel
from ..film import Film

OFFSETS = ((1, 0), (-1, 0), (0, 1), (0, -1))  # the neighbours of a pixel, in the offsets' order


class GradientFilms:
    """Per-pixel accumulators of a gradient-domain render (each a film.Film of the crop, only the
    base with AOVs): base (the path-traced image, direct light included), indirect (base less the direct light), direct, dx and
    dy (of the indirect part: dx at (x, y) estimates I(x + 1, y) - I(x, y), 2 samples per spp where
    both sides are inside the film)."""

    NAMES = ("base", "indirect", "direct", "dx", "dy")

    def __init__(self, width, height):
        for name in self.NAMES:  # the AOVs are read from the base film alone
            setattr(self, name, Film(width, height, aovs=name == "base"))

    @staticmethod
    def bytes_per_pixel():
        return Film.bytes_per_pixel() + 4 * Film.bytes_per_pixel(aovs=False)


def add_gradients(ctx, buf, films, n, G, scale=1.0):
    """Add a wave's n base samples (buf: index, L, L_cam, aov) and gradient samples scale x G (n, 4,
    3), G[:, o] an estimate of I(p + e) - I(p) for offset e = OFFSETS[o], to `films`: dx at (x, y)
    gets the +x sample of (x, y) and minus the -x sample of (x + 1, y) (where x + 1 is inside the
    film), and dy likewise."""
    arrays = lambda f: (f.count, f.sum, f.sumsq, f.aov)  # noqa: E731
    _add_wave(buf.index[:n], buf.L[:n], buf.L_cam[:n], buf.aov[:n], G, float(scale), int(ctx.crop[2]),
              tuple(arrays(getattr(films, name)) for name in GradientFilms.NAMES), numba.get_num_threads())


@jit
def _add(film, p, v0, v1, v2, aov, i):
    """One sample of value (v0, v1, v2) (and the AOVs of sample i, where the film keeps them).
    Called, not inlined by Numba (LLVM inlines it): a helper inlined into a parallel loop that
    unpacks a tuple of arrays loses its writes on the pinned Numba (tests/test_seams.py)."""
    count, s, sq, a = film
    count[p] += 1.0
    s[p, 0] += v0
    s[p, 1] += v1
    s[p, 2] += v2
    sq[p, 0] += v0 * v0
    sq[p, 1] += v1 * v1
    sq[p, 2] += v2 * v2
    for c in range(a.shape[1]):
        a[p, c] += aov[i, c]


@kernel
def _add_wave(pix, full, cam, aov, G, scale, cw, films, parts):
    """add_gradients' sums: each of `parts` threads takes a range of pixels and scans the samples
    twice, so that every pixel of every film receives its samples in the order film.Film.add gives
    them (base, direct and indirect, then +x and +y, then -x and -y from the neighbour): the sums
    of one film.Film.add per film and offset, bit for bit."""
    base = films[0]
    indirect = films[1]
    direct = films[2]
    dx = films[3]
    dy = films[4]
    npix = base[0].shape[0]
    n = pix.shape[0]
    for part in prange(parts):
        lo = part * npix // parts
        hi = (part + 1) * npix // parts
        for i in range(n):
            p = pix[i]
            if p < lo or p >= hi:
                continue
            _add(base, p, full[i, 0], full[i, 1], full[i, 2], aov, i)
            _add(direct, p, cam[i, 0], cam[i, 1], cam[i, 2], aov, i)
            _add(indirect, p, full[i, 0] - cam[i, 0], full[i, 1] - cam[i, 1], full[i, 2] - cam[i, 2], aov, i)
            _add(dx, p, scale * G[i, 0, 0], scale * G[i, 0, 1], scale * G[i, 0, 2], aov, i)
            _add(dy, p, scale * G[i, 2, 0], scale * G[i, 2, 1], scale * G[i, 2, 2], aov, i)
        for i in range(n):  # the gradient between p - e and p, kept at p - e where that is in the film
            p = pix[i]
            q = p - 1
            if p % cw >= 1 and q >= lo and q < hi:
                _add(dx, q, -(scale * G[i, 1, 0]), -(scale * G[i, 1, 1]), -(scale * G[i, 1, 2]), aov, i)
            q = p - cw
            if p >= cw and q >= lo and q < hi:
                _add(dy, q, -(scale * G[i, 3, 0]), -(scale * G[i, 3, 1]), -(scale * G[i, 3, 2]), aov, i)
