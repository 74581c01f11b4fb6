"""Chi-square goodness-of-fit tests for samplers, in the manner of Mitsuba 3's `chi2` module.

A sampler of directions on the unit sphere is checked against its claimed density: N samples
are histogrammed on a grid in (cos theta, phi), the density is integrated over every cell by
quadrature, cells with small expected counts are pooled, and Pearson's statistic gives a
p-value that is compared with a significance level corrected for the number of tests in the
suite (Sidak). Samplers may fail: failed samples go to a separate bin whose expected mass is
1 - (integral of the pdf).

Conventions
-----------
- `sample(u)`: u (n, k) float64 uniform in [0, 1) -> directions (n, 3) float64, unit length;
  a row that is not finite or has zero length is a failed sample.
- `pdf(dirs)`: dirs (n, 3) float64 unit -> (n,) float64, density per unit solid angle.
- Cells: `res = (n_z, n_phi)`, both odd, uniform in z = cos theta in [-1, 1] and in
  phi = atan2(y, x) in [-pi, pi). The grid's pole is +z.

Quadrature
----------
Cells are integrated in (theta, phi) with the Jacobian sin theta, by 2x2-point Gauss-Legendre
panels that are split adaptively (each panel against its four children) until the error
estimate is small against the counting noise: BSDF densities have narrow peaks (small
roughness) and jumps along curves (at the horizon, where a microfacet normal crosses it).
theta = pi / 2 is always a panel edge and Gauss points never sit on an edge, so the jump at the
horizon costs nothing.
"""
import functools
import math

import numpy as np
from scipy import stats

from .stats import sidak

_GL_X = np.array([-1.0, 1.0]) / math.sqrt(3.0)  # 2-point Gauss-Legendre nodes on [-1, 1]


# --- Pearson's test on a histogram ---------------------------------------------------------------
def pooled_chi2(observed, expected, min_expected=5.0):
    """Pearson's chi-square statistic with cells of small expected count pooled.

    observed, expected : arrays of the same shape (counts; expected need not be integral).
    Cells with expected < min_expected are summed into one pooled cell; if that one is still
    below min_expected it joins the smallest regular cell. Returns a dict with `stat`, `dof`,
    `p_value`, `zero_hits` (samples in cells of zero expected count) and `contrib`
    (per-cell (o - e)^2 / e over the unpooled cells, for reports).
    """
    o = np.asarray(observed, dtype=np.float64).ravel()
    e = np.asarray(expected, dtype=np.float64).ravel()
    zero_hits = int(o[e <= 0.0].sum())
    small = e < min_expected
    o_reg, e_reg = list(o[~small]), list(e[~small])
    o_pool, e_pool = o[small].sum(), e[small].sum()
    if e_pool > 0.0:
        if e_pool < min_expected and e_reg:
            i = int(np.argmin(e_reg))
            o_reg[i] += o_pool
            e_reg[i] += e_pool
        else:
            o_reg.append(o_pool)
            e_reg.append(e_pool)
    o_reg, e_reg = np.array(o_reg), np.array(e_reg)
    stat = float(np.sum((o_reg - e_reg) ** 2 / e_reg)) if e_reg.size else 0.0
    dof = max(e_reg.size - 1, 1)
    contrib = np.zeros_like(e)
    pos = e > 0.0
    contrib[pos] = (o[pos] - e[pos]) ** 2 / e[pos]
    contrib[~pos & (o > 0.0)] = np.inf
    return dict(
        stat=stat,
        dof=dof,
        p_value=float(stats.chi2.sf(stat, dof)),
        zero_hits=zero_hits,
        contrib=contrib.reshape(np.shape(observed)),
    )


def histogram_test(observed, expected, ntests=1, significance=0.01, labels=None):
    """Chi-square test of a histogram against expected counts (any shape).

    Returns (passed, message). `labels(i)` may name flat cell i in the report.
    """
    res = pooled_chi2(observed, expected)
    alpha = sidak(ntests, significance)
    o = np.asarray(observed, dtype=np.float64).ravel()
    e = np.asarray(expected, dtype=np.float64).ravel()
    lines = [
        f"chi2 = {res['stat']:.1f}, dof = {res['dof']}, p = {res['p_value']:.3g}, "
        f"level = {alpha:.3g} ({ntests} tests)"
    ]
    passed = res["p_value"] >= alpha and res["zero_hits"] == 0
    if res["zero_hits"]:
        lines.append(f"{res['zero_hits']} samples fell in cells of zero expected count")
    if not passed:
        worst = np.argsort(res["contrib"].ravel())[::-1][:8]
        lines.append("worst cells: (o - e)^2 / e, observed, expected")
        for i in worst:
            name = labels(int(i)) if labels else f"cell {int(i)}"
            lines.append(f"  {name}: {res['contrib'].ravel()[i]:.1f}, {o[i]:.0f}, {e[i]:.1f}")
    return passed, "\n".join(lines)


# --- Adaptive quadrature over the sphere on the histogram grid -----------------------------------
def _gl_panels(fn, t0, t1, p0, p1):
    """2x2-point Gauss-Legendre integral of fn(dir) sin(theta) over panels in (theta, phi).

    t0, t1, p0, p1 : (k,) panel bounds. Returns (k,) or (k, c) integrals per unit solid angle.
    """
    tm, th = 0.5 * (t0 + t1), 0.5 * (t1 - t0)
    pm, ph = 0.5 * (p0 + p1), 0.5 * (p1 - p0)
    t = (tm[:, None] + th[:, None] * _GL_X[None, :])[:, :, None]  # (k, 2, 1)
    p = (pm[:, None] + ph[:, None] * _GL_X[None, :])[:, None, :]  # (k, 1, 2)
    st = np.sin(t)
    dirs = np.empty((t0.size, 2, 2, 3))
    dirs[..., 0] = st * np.cos(p)
    dirs[..., 1] = st * np.sin(p)
    dirs[..., 2] = np.cos(t)
    f = np.asarray(fn(dirs.reshape(-1, 3)), dtype=np.float64)
    w = np.broadcast_to(st * (th * ph)[:, None, None], dirs.shape[:3]).reshape(-1)  # GL weights 1
    if f.ndim == 1:
        return (f * w).reshape(t0.size, 4).sum(axis=1)
    return (f * w[:, None]).reshape(t0.size, 4, f.shape[-1]).sum(axis=1)


def _split(t0, t1, p0, p1):
    """The four children of each panel, as bound arrays of length 4k (child-major per panel)."""
    tm, pm = 0.5 * (t0 + t1), 0.5 * (p0 + p1)
    c_t0 = np.stack([t0, t0, tm, tm], axis=1).ravel()
    c_t1 = np.stack([tm, tm, t1, t1], axis=1).ravel()
    c_p0 = np.stack([p0, pm, p0, pm], axis=1).ravel()
    c_p1 = np.stack([pm, p1, pm, p1], axis=1).ravel()
    return c_t0, c_t1, c_p0, c_p1


class SphereGrid:
    """The histogram grid in (z = cos theta, phi) and an adaptive quadrature over its cells.

    res  : (n_z, n_phi), both odd.
    step : largest side of the initial quadrature panels, radians. Every cell is split into
           panels (an even number along theta, so theta = pi / 2 is a panel edge); each panel is
           integrated with 2x2 Gauss-Legendre points and again as its four children, whose
           difference estimates the error. Panels are split further where the error exceeds
           the tolerances (`integrate`): near peaks and along curves where the integrand jumps.
    """

    def __init__(self, res=(31, 61), step=0.05):
        self.res = (int(res[0]), int(res[1]))
        if self.res[0] % 2 == 0 or self.res[1] % 2 == 0:
            raise ValueError(f"grid resolution must be odd, got {self.res}")
        self.step = float(step)
        nz, nphi = self.res
        self.z_edges = np.linspace(-1.0, 1.0, nz + 1)
        self.phi_edges = np.linspace(-math.pi, math.pi, nphi + 1)
        theta_edges = np.arccos(self.z_edges)  # z-cell j spans theta in [edge j+1, edge j]
        ts, tc = [], []
        for j in range(nz):
            a, b = theta_edges[j + 1], theta_edges[j]
            k = 2 * math.ceil((b - a) / self.step / 2.0)
            ts.append(np.linspace(a, b, k + 1))
            tc.append(np.full(k, j))
        ps, pc = [], []
        for j in range(nphi):
            a, b = self.phi_edges[j], self.phi_edges[j + 1]
            k = math.ceil((b - a) / self.step)
            ps.append(np.linspace(a, b, k + 1))
            pc.append(np.full(k, j))
        # Base intervals along theta and phi; panels are their tensor product
        self._theta = (
            np.concatenate([s[:-1] for s in ts]),
            np.concatenate([s[1:] for s in ts]),
            np.concatenate(tc),
        )
        self._phi = (
            np.concatenate([s[:-1] for s in ps]),
            np.concatenate([s[1:] for s in ps]),
            np.concatenate(pc),
        )

    def _base_panels(self, breaks):
        """Base panels, with theta intervals split at the polar angles of the z-values `breaks`
        (circles where the integrand is known to jump)."""
        t0, t1, cz = self._theta
        for zb in breaks:
            tb = math.acos(min(max(float(zb), -1.0), 1.0))
            inside = (t0 < tb) & (tb < t1)
            if inside.any():
                t0 = np.concatenate([t0, np.full(inside.sum(), tb)])
                t1 = np.concatenate([np.where(inside, tb, t1), t1[inside]])
                cz = np.concatenate([cz, cz[inside]])
        p0, p1, cp = self._phi
        nphi = self.res[1]
        return (
            np.repeat(t0, p0.size),
            np.repeat(t1, p0.size),
            np.tile(p0, t0.size),
            np.tile(p1, t0.size),
            (np.repeat(cz, p0.size) * nphi + np.tile(cp, t0.size)).astype(np.int64),
        )

    def integrate(self, fn, tol_cell=None, tol_total=None, max_rounds=12, breaks=()):
        """Integrals of fn over every cell, per unit solid angle, refined until accurate enough.

        fn        : dirs (m, 3) float64 -> (m,) or (m, c) float64.
        tol_cell  : cells (n_z * n_phi,) or (n_z * n_phi, c) -> (n_z * n_phi,) absolute error
                    allowed per cell, or None.
        tol_total : totals (float or (c,)) -> absolute error allowed on the sum of all cells,
                    or None.
        breaks    : z-values of circles where fn may jump; panels get an edge there (z = 0
                    is always one).
        Returns (cells, err, info): cells and err with shape (n_z, n_phi) or (n_z, n_phi, c);
        err is the summed |children - parent| of the final panels, an upper estimate of the
        error of `cells`; info holds `converged`, `rounds`, `evaluations`.
        """
        ncell = self.res[0] * self.res[1]
        t0, t1, p0, p1, cell = self._base_panels(breaks)
        v = _gl_panels(fn, t0, t1, p0, p1)  # value of each leaf panel
        evals = 4 * t0.size
        converged = False
        for rnd in range(max_rounds + 1):
            # Children of every new leaf: their sum is the leaf's refined value
            ch = _split(t0, t1, p0, p1)
            cv = _gl_panels(fn, *ch)
            evals += 4 * ch[0].size
            cv = cv.reshape((t0.size, 4) + cv.shape[1:])
            fine = cv.sum(axis=1)
            err = np.abs(fine - v)
            err_max = err if err.ndim == 1 else err.max(axis=1)
            if rnd == 0:
                leaves = [t0, t1, p0, p1, cell, fine, err_max, cv]
            else:
                new = [t0, t1, p0, p1, cell, fine, err_max, cv]
                leaves = [np.concatenate([a, b]) for a, b in zip(leaves, new)]
            L_t0, L_t1, L_p0, L_p1, L_cell, L_fine, L_err, L_cv = leaves
            # Per-cell and total values and error estimates
            cells = _cell_sum(L_cell, L_fine, ncell)
            e_cell = np.bincount(L_cell, L_err, minlength=ncell)
            n_cell = np.bincount(L_cell, minlength=ncell)
            thresh = np.full(L_cell.size, np.inf)
            if tol_cell is not None:
                tc = np.asarray(tol_cell(cells), dtype=np.float64)
                bad = e_cell > tc
                share = np.where(bad, tc / np.maximum(n_cell, 1), np.inf)
                thresh = np.minimum(thresh, share[L_cell])
            if tol_total is not None:
                tt = float(tol_total(cells.sum(axis=0)))
                if e_cell.sum() > tt:
                    thresh = np.minimum(thresh, tt / L_cell.size)
            refine = L_err > thresh
            if not refine.any():
                converged = True
                break
            if rnd == max_rounds:
                break
            # Split the leaves that carry too much error; their children are already known
            keep = ~refine
            t0, t1, p0, p1 = _split(L_t0[refine], L_t1[refine], L_p0[refine], L_p1[refine])
            cell = np.repeat(L_cell[refine], 4)
            v = L_cv[refine].reshape((-1,) + L_cv.shape[2:])
            leaves = [a[keep] for a in leaves]
        shape = self.res + cells.shape[1:]
        err_cells = np.bincount(L_cell, L_err, minlength=ncell)
        err_out = err_cells.reshape(self.res)
        if cells.ndim == 2:
            err_out = np.broadcast_to(err_out[..., None], shape).copy()
        info = dict(converged=converged, rounds=rnd, evaluations=evals, leaves=L_cell.size)
        return cells.reshape(shape), err_out, info

    def bin(self, dirs):
        """Flat cell index of each direction (n,) int64, -1 for failed samples."""
        d = np.asarray(dirs, dtype=np.float64)
        ok = np.all(np.isfinite(d), axis=1) & (np.sum(d * d, axis=1) > 0.0)
        d = np.where(ok[:, None], d, 0.0)
        nz, nphi = self.res
        z = np.clip(d[:, 2], -1.0, 1.0)
        iz = np.clip(((z + 1.0) * 0.5 * nz).astype(np.int64), 0, nz - 1)
        phi = np.arctan2(d[:, 1], d[:, 0])
        ip = np.clip(((phi + math.pi) / (2.0 * math.pi) * nphi).astype(np.int64), 0, nphi - 1)
        idx = iz * nphi + ip
        idx[~ok] = -1
        return idx

    def label(self, i):
        """Readable name of flat cell i (the index past the last cell is the failed bin)."""
        nz, nphi = self.res
        if i >= nz * nphi:
            return "failed samples"
        iz, ip = divmod(i, nphi)
        return (
            f"z [{self.z_edges[iz]:+.3f}, {self.z_edges[iz + 1]:+.3f}] "
            f"phi [{self.phi_edges[ip]:+.3f}, {self.phi_edges[ip + 1]:+.3f}]"
        )


def _cell_sum(cell, val, ncell):
    """Sum of panel values per cell: (ncell,) or (ncell, c)."""
    if val.ndim == 1:
        return np.bincount(cell, val, minlength=ncell)
    return np.stack([np.bincount(cell, val[:, c], minlength=ncell) for c in range(val.shape[1])], 1)


@functools.lru_cache(maxsize=4)
def sphere_grid(res=(31, 61), step=0.05):
    """A shared `SphereGrid` (tests reuse its panel tables)."""
    return SphereGrid(res, step)


class ChiSquareTest:
    """Chi-square test of a direction sampler against its density over the sphere.

    sample : u (n, sample_dim) -> dirs (n, 3) (failed rows: non-finite or zero).
    pdf    : dirs (m, 3) -> (m,) per unit solid angle.
    n      : number of samples; seed : for np.random.default_rng (reproducible).
    quad   : the quadrature is refined until its error estimate is below `quad` times the
             counting noise sqrt(expected) in every cell and in the failed bin.
    breaks : z-values of circles along which the pdf jumps (besides z = 0), made panel edges.

    After `run`, the instance holds `observed` and `expected` (n_z * n_phi + 1 cells, the last
    the failed bin), `pdf_integral`, `quad_error` (estimated error of the integral), `p_value`
    and `message` (a readable report, with the worst cells when the test fails).
    """

    def __init__(self, sample, pdf, sample_dim=3, n=1_000_000, res=(31, 61), step=0.05,
                 seed=0, quad=0.1, breaks=()):
        self.sample, self.pdf = sample, pdf
        self.breaks = tuple(breaks)
        self.sample_dim, self.n, self.seed = int(sample_dim), int(n), seed
        self.grid = sphere_grid(tuple(res), float(step))
        self.quad = float(quad)
        self.message = ""

    def tabulate(self):
        """Histogram the samples and integrate the pdf over the cells."""
        rng = np.random.default_rng(self.seed)
        u = rng.random((self.n, self.sample_dim))
        idx = self.grid.bin(self.sample(u))
        ncell = self.grid.res[0] * self.grid.res[1]
        self.observed = np.bincount(np.where(idx < 0, ncell, idx), minlength=ncell + 1).astype(
            np.float64
        )
        n, q = self.n, self.quad
        cells, err, self.quad_info = self.grid.integrate(
            self.pdf,
            tol_cell=lambda c: q * np.sqrt(np.maximum(n * c, 5.0)) / n,
            tol_total=lambda tot: q * math.sqrt(max(n * (1.0 - tot), 5.0)) / n,
            breaks=self.breaks,
        )
        self.pdf_integral = float(cells.sum())
        self.quad_error = float(err.sum())
        # Expected counts; the failed bin gets the mass the pdf leaves out
        self.expected = np.append(cells.ravel(), max(1.0 - self.pdf_integral, 0.0)) * n

    def run(self, ntests=1, significance=0.01):
        """Tabulate and test; returns True when the sampler agrees with the pdf."""
        self.tabulate()
        passed, msg = histogram_test(
            self.observed, self.expected, ntests, significance, labels=self.grid.label
        )
        self.p_value = pooled_chi2(self.observed, self.expected)["p_value"]
        info = self.quad_info
        head = (
            f"pdf integral = {self.pdf_integral:.6f} (quadrature error <= {self.quad_error:.2g}, "
            f"{info['evaluations']} evaluations, {info['rounds']} rounds), "
            f"failed samples {self.observed[-1]:.0f} / {self.n}"
        )
        if not info["converged"]:
            passed = False
            head += "\nquadrature did not reach its tolerance: expected counts are unreliable"
        if self.pdf_integral > 1.0 + self.quad_error + 1e-9:
            passed = False
            head += "\npdf integrates to more than 1"
        self.message = head + "\n" + msg
        return passed
