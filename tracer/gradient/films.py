"""What a gradient-domain render accumulates, whatever its shift: the base image, its indirect and
direct parts, and the dx, dy gradient images (GradientFilms), and how a wave's base samples and
gradient samples are added to them (add_gradients)."""
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


def add_gradients(ctx, buf, films, n, G):
    """Add a wave's n base samples (buf: index, L, L_cam, aov) and gradient samples G (n, 4, 3),
    G[:, o] an estimate of I(p + e) - I(p) for offset e = OFFSETS[o], to `films`: dx at (x, y) gets
    the +x sample of (x, y) and minus the -x sample of (x + 1, y) (where x + 1 is inside the film),
    and dy likewise."""
    cw = int(ctx.crop[2])
    pix, aov = buf.index[:n], buf.aov[:n]
    full, cam = buf.L[:n], buf.L_cam[:n]
    films.base.add(pix, full, aov)
    films.direct.add(pix, cam, aov)
    films.indirect.add(pix, full - cam, aov)
    px, py = pix % cw, pix // cw
    for o, (ox, oy) in enumerate(OFFSETS):
        film = films.dx if ox else films.dy
        if ox + oy > 0:
            film.add(pix, G[:, o], aov)
        else:  # the gradient between p - e and p, stored at p - e where that is inside the film
            keep = (px if ox else py) >= 1
            film.add(pix[keep] - (1 if ox else cw), -G[keep, o], aov[keep])
