"""ns per diffuse vertex: float32 structure-of-arrays lanes against the path kernel's `shade`.

    python -m bench.lane_vertex --asm           # mitsuba-cornell, 256x256, 4 spp of hits
    python -m bench.lane_vertex --asm --zmm     # the same with 512-bit vectors allowed
    NUMBA_SLP_VECTORIZE=1 python -m bench.lane_vertex --out bench/results/lane_vertex_slp.json

Renders the scene once on the wavefront (`path_loop="wave"`) and keeps every call of
tracer.integrators.path.shade with its inputs: the hits of one bounce of a wave and the path state
before it. Then it times, on the same hits, at 1 and at 2 Numba threads:

- `shade`: the path kernel itself (float64, every material, the guide's mixture, AOVs), replayed
  call by call from the captured state;
- this module's diffuse vertex over SoA float32 rows [field, lane]: emission with its MIS weight,
  a light sample (alias table, uniform on the triangle) with MIS, a cosine bounce through a
  branch-free frame, and the roulette from rr_depth, each lane's random numbers hashed from a
  32-bit key, written out as the next ray and the shadow ray. Its variants: `flat` (one prange
  over the lanes: LLVM's loop vectoriser packs them, with gathers, once the parfor marks the arrays
  noalias) or `blocked` (blocks of LANES lanes, 16 with AVX-512, else 8, whose inner loop LLVM
  unrolls and then leaves to the SLP vectoriser, off unless NUMBA_SLP_VECTORIZE=1); `fast`:
  fastmath arcp, contract and nsz (not nnan / ninf: the renderer relies on isfinite); `poly`: a
  polynomial sincos in place of libm's.

`same_work` checks that the lanes compute what shade computes (z-scores of the mean light-sample
value and emission per vertex); every variant's outputs are compared with the first's. Figures are
the minimum over --repeat timed runs of every batch, in ns per vertex (the padding lanes of the
blocked variants count as work, not as vertices). `--asm` counts the packed instructions of each
variant's loop body by register width. The table goes to bench/results/lane_vertex.json.
"""
import argparse
import math
import os
import re
import subprocess
import sys
import textwrap
import time

import numba
import numpy as np
from numba import njit, prange

import tracer
from tracer.engine import lanes, sampling32
from tracer.guiding.records import Records
from tracer.integrators import path as path_mod
from tracer.wave import Continuation, PathState, ShadowRays

from . import atomic, throughput

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "bench", "results", "lane_vertex.json")


def _cpuinfo():
    """The text of /proc/cpuinfo ("" where there is none)."""
    try:
        with open("/proc/cpuinfo") as f:
            return f.read()
    except OSError:
        return ""


LANES = 16 if "avx512f" in _cpuinfo() else 8
FLAGS = {"arcp", "contract", "nsz"}

# float32 constants (a Python float literal is float64 in Numba and would widen the arithmetic), the
# lanes' random numbers and polynomial sincos: the engine's (tracer.engine.sampling32)
F = sampling32.F
ZERO, ONE, HALF = F(0.0), F(1.0), F(0.5)
INV_PI, TWO_PI, TINY, SHORT = sampling32.INV_PI, F(2.0 * math.pi), sampling32.TINY, sampling32.SHORT
Q_MAX = F(sampling32.RR_MAX)
U32 = np.uint32
_rand = sampling32.rand32  # float32 in [0, 1) from a 32-bit key and a dimension
sincos_poly = sampling32.sincos2pi
alias_table = lanes.alias_table
# random dimensions of a bounce (tracer.rng's table: light choice, light position, direction, roulette)
D_LIGHT, D_POS, D_DIR, D_RR = sampling32.D_LIGHT, sampling32.D_POS, sampling32.D_DIR, sampling32.D_RR
BOUNCE, BLOCK = sampling32.BOUNCE, sampling32.BLOCK


@njit(inline="always")
def sincos_libm(u):
    a = u * TWO_PI
    return math.cos(a), math.sin(a)


# The vertex of lane k, as source text placed inside each loop form below. It is not a function
# that the loops call: Numba's IR inliner passes arrays into an inlined function as copies of
# their names, and the prange loop's parfor then no longer marks its arrays `noalias`, without
# which LLVM cannot vectorise a loop that gathers from one array and stores to another (measured:
# "cannot identify array bounds"); a call that is not inlined keeps the loop scalar ("call
# instruction cannot be vectorized").
VERTEX = """
p = prim[k]
hit_ok = p >= 0
pc = p if hit_ok else 0
dx, dy, dz = ray[3, k], ray[4, k], ray[5, k]
t, b1, b2 = hit[0, k], hit[1, k], hit[2, k]
x0 = tri[0, pc] + b1 * tri[3, pc] + b2 * tri[6, pc]
x1 = tri[1, pc] + b1 * tri[4, pc] + b2 * tri[7, pc]
x2 = tri[2, pc] + b1 * tri[5, pc] + b2 * tri[8, pc]
nx, ny, nz = nrm[0, pc], nrm[1, pc], nrm[2, pc]
cos_o = -(dx * nx + dy * ny + dz * nz)
sgn = ONE if cos_o >= ZERO else -ONE
fx, fy, fz = nx * sgn, ny * sgn, nz * sgn
br, bg, bb = path[0, k], path[1, k], path[2, k]
prev_pdf = path[3, k]
depth = ipath[0, k]
key = U32(ipath[1, k])
base = BOUNCE + BLOCK * depth
on = (lim[1] < 0) | (depth + 1 < lim[1])  # the path may go on past this vertex (max_depth)

# emission (one-sided), MIS-weighted against the light sample that could have found it
sel, area = tl[0, pc], tl[1, pc]
lit = hit_ok & (cos_o > ZERO) & (sel > ZERO)
pl = sel * t * t / max(area * cos_o, TINY)
pp = prev_pdf * prev_pdf
w_e = (ONE if depth == 0 else pp / max(pp + pl * pl, TINY)) if lit else ZERO
L[0, k] += br * emit[0, pc] * w_e
L[1, k] += bg * emit[1, pc] * w_e
L[2, k] += bb * emit[2, pc] * w_e

# a light sample: an emissive triangle from the alias table, a point uniform on it
u_sel = _rand(key, base + D_LIGHT)
nl = alias_p.shape[0]
us = u_sel * F(nl)
j = min(np.int32(us), np.int32(nl - 1))
lj = alias_i[0, j] if us - F(j) < alias_p[j] else alias_i[1, j]
su = math.sqrt(_rand(key, base + D_POS))
lb1 = ONE - su
lb2 = _rand(key, base + D_POS + 1) * su
wx = tri[0, lj] + lb1 * tri[3, lj] + lb2 * tri[6, lj] - x0
wy = tri[1, lj] + lb1 * tri[4, lj] + lb2 * tri[7, lj] - x1
wz = tri[2, lj] + lb1 * tri[5, lj] + lb2 * tri[8, lj] - x2
d2 = max(wx * wx + wy * wy + wz * wz, TINY)
inv_d = ONE / math.sqrt(d2)
wx, wy, wz = wx * inv_d, wy * inv_d, wz * inv_d
cos_l = -(wx * nrm[0, lj] + wy * nrm[1, lj] + wz * nrm[2, lj])
cos_s = wx * fx + wy * fy + wz * fz
ok = hit_ok & on & (cos_l > ZERO) & (cos_s > ZERO)
pls = tl[0, lj] * d2 / max(tl[1, lj] * cos_l, TINY)
pb = cos_s * INV_PI
w_l = pls / max(pls * pls + pb * pb, TINY) * pls
g = (cos_s * INV_PI * w_l / max(pls, TINY)) if ok else ZERO
ox, oy, oz = x0 + fx * tl[2, pc], x1 + fy * tl[2, pc], x2 + fz * tl[2, pc]
out[0, k], out[1, k], out[2, k] = ox, oy, oz
out[6, k], out[7, k], out[8, k] = wx, wy, wz
out[9, k] = d2 * inv_d * SHORT
out[10, k] = br * alb[0, pc] * emit[0, lj] * g
out[11, k] = bg * alb[1, pc] * emit[1, lj] * g
out[12, k] = bb * alb[2, pc] * emit[2, lj] * g

# the cosine bounce, in the frame of the arrival side's normal (Duff et al. 2017)
u2 = _rand(key, base + D_DIR)
c, s = sincos(_rand(key, base + D_DIR + 1))
r = math.sqrt(u2)
lx, ly = r * c, r * s
lz = math.sqrt(max(ZERO, ONE - u2))
sg = ONE if fz >= ZERO else -ONE
a = -ONE / (sg + fz)
bq = fx * fy * a
wix = (ONE + sg * fx * fx * a) * lx + bq * ly + fx * lz
wiy = sg * bq * lx + (sg + fy * fy * a) * ly + fy * lz
wiz = -sg * fx * lx - fy * ly + fz * lz
nbr, nbg, nbb = br * alb[0, pc], bg * alb[1, pc], bb * alb[2, pc]

# the roulette of the new bounce
qq = min(max(nbr, max(nbg, nbb)), Q_MAX) if depth + 1 >= lim[0] else ONE
go = hit_ok & on & (lz > ZERO) & (_rand(key, base + D_RR) < qq)
inv_q = ONE / max(qq, TINY)
out[3, k], out[4, k], out[5, k] = wix, wiy, wiz
path[0, k], path[1, k], path[2, k] = nbr * inv_q, nbg * inv_q, nbb * inv_q
path[3, k] = lz * INV_PI
ipath[0, k] = np.int32(depth + 1)
alive[k] = go
"""

LOOPS = {
    False: """
def lanes(ray, hit, prim, path, ipath, L, tri, nrm, alb, emit, tl, alias_p, alias_i, out, alive, lim):
    for k in prange(prim.shape[0]):
{body}
""",
    True: """
def lanes(ray, hit, prim, path, ipath, L, tri, nrm, alb, emit, tl, alias_p, alias_i, out, alive, lim):
    for blk in prange(prim.shape[0] // LANES):
        for lane in range(LANES):
            k = blk * LANES + lane
{body}
""",
}


def make_kernel(blocked, fast, poly):
    """A lane kernel over SoA rows [field, lane] (the module docstring): `blocked` (blocks of LANES
    lanes, the inner loop left to LLVM) or one prange over lanes; `fast`: fastmath arcp, contract,
    nsz; `poly`: the polynomial sincos (else libm's)."""
    src = LOOPS[blocked].format(body=textwrap.indent(VERTEX.strip("\n"), " " * (12 if blocked else 8)))
    scope = dict(globals(), sincos=sincos_poly if poly else sincos_libm)
    exec(compile(src, f"<lane kernel blocked={blocked}>", "exec"), scope)
    return njit(parallel=True, fastmath=FLAGS if fast else False, nogil=True, error_model="numpy")(scope["lanes"])


VARIANTS = {  # name: (blocked, fastmath, polynomial sincos)
    "flat": (False, False, False),
    "flat-fast": (False, True, False),
    "flat-fast-poly": (False, True, True),
    "blocked": (True, False, False),
    "blocked-fast": (True, True, False),
    "blocked-fast-poly": (True, True, True),
}


def capture(name, spp, width, height):
    """Render `name` on the wavefront (max depth 8, rr depth 5) and return the arguments of every
    call of path.shade, each array copied as it was before the call."""
    over = {k: v for k, v in (("width", width), ("height", height)) if v}
    scene = tracer.load_scene(throughput.scene_spec(name)["obj"], **over)
    kw = dict(max_depth=8, rr_depth=5, path_loop="wave")
    tracer.render(scene, spp=1, **kw)  # compile or load the kernels first
    calls = []
    shade = path_mod.shade

    def keep(*args):
        calls.append(tuple(a.copy() if isinstance(a, np.ndarray) else a for a in flat(args)))
        return shade(*args)

    path_mod.shade = keep
    try:
        tracer.render(scene, spp=spp, **kw)
    finally:
        path_mod.shade = shade
    return calls


def lane_scene(surf, lt):
    """The scene as the lane kernel reads it: tri (9, F) v0, e1, e2; nrm (3, F); alb (3, F) diffuse
    reflectance; emit (3, F) radiance; tl (3, F) light selection probability, area, ray offset;
    and the alias table over the emissive triangles: the probability of keeping column j, and
    (2, columns) triangle ids, row 0 column j's own triangle, row 1 its alias's."""
    v = surf.tri
    tri = np.concatenate([v[:, 0].T, (v[:, 1] - v[:, 0]).T, (v[:, 2] - v[:, 0]).T]).astype(F)
    nrm = surf.normal.T.astype(F)
    alb = surf.mat_param[surf.material, 0:3].T.astype(F)
    nf = v.shape[0]
    emit = np.zeros((3, nf), F)
    tl = np.zeros((3, nf), F)
    tl[2] = surf.eps
    e = lt.tri
    sel = (1.0 - lt.p_env) * np.diff(lt.cdf)
    emit[:, e] = lt.radiance.T
    tl[0, e] = sel
    tl[1, e] = lt.area
    prob, alias = alias_table(sel / sel.sum())
    return tri, nrm, alb, emit, tl, prob.astype(F), np.stack([e, e[alias]]).astype(np.int32)


def limits(calls):
    """int32 [rr_depth, max_depth] of the captured render (shade's arguments 12 and 11)."""
    return np.array([calls[0][12], calls[0][11]], np.int32)


class Batch:
    """One shade call's hits and path state as SoA lanes, padded to a multiple of LANES (prim -1)."""

    def __init__(self, args):
        active, ro, rd, t, prim, b1, b2 = args[:7]
        beta, L, _, depth, prev_pdf = args[14:19]
        key = args[21]
        n = active.shape[0]
        m = -(-n // LANES) * LANES
        self.n = n
        self.ray = np.zeros((6, m), F)
        self.ray[:3, :n], self.ray[3:, :n] = ro[:n].T, rd[:n].T
        self.hit = np.zeros((3, m), F)
        self.hit[0, :n], self.hit[1, :n], self.hit[2, :n] = t[:n], b1[:n], b2[:n]
        self.prim = np.full(m, -1, np.int32)
        self.prim[:n] = prim[:n]
        self.path0 = np.zeros((4, m), F)
        self.path0[:3, :n] = beta[active].T
        self.path0[3, :n] = prev_pdf[active]
        self.ipath0 = np.zeros((2, m), np.int32)  # depth, a 32-bit key folded from the path's 64-bit one
        self.ipath0[0, :n] = depth[active]
        k64 = key[active].astype(np.uint64)
        self.ipath0[1, :n] = ((k64 ^ (k64 >> np.uint64(32))) & np.uint64(0xFFFFFFFF)).astype(np.uint32).view(np.int32)
        self.path, self.ipath = self.path0.copy(), self.ipath0.copy()
        self.L = np.zeros((3, m), F)
        self.out = np.zeros((13, m), F)
        self.alive = np.zeros(m, np.bool_)

    def reset(self):
        self.path[:] = self.path0
        self.ipath[:] = self.ipath0
        self.L[:] = 0.0

    def args(self, scene, lim):
        tri, nrm, alb, emit, tl, prob, alias = scene
        return (self.ray, self.hit, self.prim, self.path, self.ipath, self.L, tri, nrm, alb, emit, tl, prob, alias,
                self.out, self.alive, lim)


def same_work(calls, batches):
    """z-scores of the mean per vertex of the light-sample value (unoccluded) and of the emission
    found, shade's (run once on each captured call) against the lanes' (their last run): the
    two kernels estimate the same quantities with different random numbers, so |z| well below
    4 says that the lanes do the work shade does (a missing cosine, pdf or MIS weight would not)."""
    sh, em = [], []
    for c in calls:
        args = [a.copy() if isinstance(a, np.ndarray) else a for a in c]
        n, active, L = c[0].shape[0], c[0], args[15]
        before = L[active].copy()
        shade_kernel(*args)
        sh.append(np.where(args[33][:n, None], args[32][:n], 0.0).sum(axis=1))
        em.append((L[active] - before).sum(axis=1))
    lane_sh = np.concatenate([b.out[10:13, : b.n].sum(axis=0) for b in batches])
    lane_em = np.concatenate([b.L[:, : b.n].sum(axis=0) for b in batches])
    z = {}
    for name, a, b in (("light_sample", np.concatenate(sh), lane_sh), ("emission", np.concatenate(em), lane_em)):
        se = math.sqrt(a.var() / a.size + b.var() / b.size)
        z[name] = {"shade": float(a.mean()), "lanes": float(b.mean()), "z": float((b.mean() - a.mean()) / max(se, 1e-30))}
    return z


def time_shade(calls, repeat):
    """ns per vertex of `shade` replayed on the captured calls (state restored before each)."""
    mutable = [[i for i, a in enumerate(c) if isinstance(a, np.ndarray)] for c in calls]
    live = [list(c) for c in calls]
    best = math.inf
    for _ in range(repeat):
        total = 0.0
        for c, ix, args in zip(calls, mutable, live):
            for i in ix:
                args[i] = c[i].copy()
            t0 = time.perf_counter()
            shade_kernel(*args)
            total += time.perf_counter() - t0
        best = min(best, total)
    return best


def flat(args):
    """path.shade's arguments with every bundle spread, in field order: active, ray_o, ray_d, t, prim,
    b1, b2, surf, lights, guide, samples, max_depth, rr_depth, nee, the PathState (14-25), the
    Continuation (26-28), the ShadowRays (29-33), record, rec_base, the Records (36-)."""
    a = list(args)
    return tuple(a[:3] + list(a[3]) + a[4:8] + list(a[8]) + list(a[9]) + list(a[10]) + list(a[11]) + a[12:14]
                 + list(a[14]))


def shade_kernel(*a):
    """path.shade called with the flat arguments of `flat`."""
    return path_mod.shade(a[0], a[1], a[2], tuple(a[3:7]), a[7], a[8], a[9], a[10], tuple(a[11:14]),
                          PathState(*a[14:26]), Continuation(*a[26:29]), ShadowRays(*a[29:34]), a[34], a[35],
                          Records(*a[36:]))


def time_lanes(kernel, batches, scene, lim, repeat):
    best = math.inf
    for _ in range(repeat):
        total = 0.0
        for b in batches:
            b.reset()
            args = b.args(scene, lim)
            t0 = time.perf_counter()
            kernel(*args)
            total += time.perf_counter() - t0
        best = min(best, total)
    return best


def packed_counts(variant, env):
    """Packed float instructions in the assembly of the variant's parallel loop body (the parfor
    gufunc; inspect_asm shows only the launcher), counted by register width: zmm (16 float32
    lanes), ymm (8), xmm (4); and the gathers. A child process compiles the variant on a few
    lanes with NUMBA_DUMP_ASSEMBLY and `env` (e.g. NUMBA_CPU_FEATURES)."""
    out = subprocess.run([sys.executable, "-m", "bench.lane_vertex", "--dump-asm", variant], cwd=ROOT,
                         env=dict(os.environ, NUMBA_DUMP_ASSEMBLY="1", **env), capture_output=True, text=True,
                         check=True).stdout
    sections = re.split(r"\n-+ASSEMBLY ", out)
    body = "\n".join(sec for sec in sections if sec.startswith("__numba_parfor_gufunc"))
    ops = re.findall(r"^\s+(v\w+p[sd])\s+([^\n]*)", body, re.M)
    width = {"zmm": 0, "ymm": 0, "xmm": 0}
    for _, regs in ops:
        width["zmm" if "zmm" in regs else "ymm" if "ymm" in regs else "xmm"] += 1
    return dict(width, gathers=len(re.findall(r"gather", body)))


def zmm_env():
    """NUMBA_CPU_FEATURES: the host's features less prefer-256-bit (LLVM's default on Intel server
    parts, which keeps loops at 8 float32 lanes even with AVX-512)."""
    import llvmlite.binding as ll

    ll.initialize_native_target()
    return {"NUMBA_CPU_FEATURES": ll.get_host_cpu_features().flatten() + ",-prefer-256-bit"}


def _dump_asm(variant):
    m = 2 * LANES
    f32 = lambda r: np.zeros((r, m), F)  # noqa: E731
    one = lambda r: np.ones((r, 4), F)  # noqa: E731
    ray = f32(6)
    ray[5] = -1.0
    make_kernel(*VARIANTS[variant])(ray, f32(3), np.zeros(m, np.int32), f32(4), np.zeros((2, m), np.int32), f32(3),
                                    one(9), one(3), one(3), one(3), one(3), np.ones(2, F), np.zeros((2, 2), np.int32),
                                    f32(13), np.zeros(m, np.bool_), np.array([5, 8], np.int32))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.lane_vertex", description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="mitsuba-cornell")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--asm", action="store_true", help="count the packed instructions of each variant")
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--zmm", action="store_true",
                    help="run again with the host's CPU features less prefer-256-bit (NUMBA_CPU_FEATURES), so that "
                         "LLVM may use 512-bit vectors; writes lane_vertex_zmm.json unless --out is given")
    ap.add_argument("--dump-asm", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.dump_asm:
        return _dump_asm(a.dump_asm)
    if a.zmm:
        rest = [x for x in (sys.argv[1:] if argv is None else argv) if x != "--zmm"]
        if "--out" not in rest:
            rest += ["--out", OUT.replace(".json", "_zmm.json")]
        os.execvpe(sys.executable, [sys.executable, "-m", "bench.lane_vertex", *rest], dict(os.environ, **zmm_env()))
    calls = capture(a.scene, a.spp, a.width, a.height)
    surf, lt = calls[0][7], calls[0][8]
    if np.any(surf.mat_type != 0) or surf.uv.shape[0] or surf.vn.shape[0]:
        print(f"note: {a.scene} holds non-diffuse materials or vertex data; the lanes shade every triangle diffuse")
    scene = lane_scene(surf, lt)
    lim = limits(calls)
    batches = [Batch(c) for c in calls]
    n = sum(b.n for b in batches)
    print(f"{a.scene}: {len(calls)} shade calls, {n} vertices; {LANES} lanes a block; "
          f"SLP vectorizer {'on' if numba.config.SLP_VECTORIZE else 'off'}; "
          f"{'512' if '-prefer-256-bit' in os.environ.get('NUMBA_CPU_FEATURES', '') else '256'}-bit vectors preferred")
    rows = []
    kernels = {}
    ref = None
    for name in a.variants.split(","):
        kernels[name] = make_kernel(*VARIANTS[name])
        for b in batches:  # compile, and keep the outputs for the comparison
            b.reset()
            kernels[name](*b.args(scene, lim))
        outs = np.concatenate([b.out[:, : b.n] for b in batches], axis=1)
        ref = outs if ref is None else ref
        rows.append({"variant": name, "max_diff_vs_first": float(np.max(np.abs(outs - ref)))})
    z = same_work(calls, batches)
    for k, v in z.items():
        print(f"same work, {k}: shade {v['shade']:.5g}, lanes {v['lanes']:.5g} a vertex (z = {v['z']:+.2f})")
    for threads in (1, 2):
        numba.set_num_threads(threads)
        t_shade = time_shade(calls, a.repeat)
        print(f"{threads} thread(s): shade {1e9 * t_shade / n:.1f} ns/vertex")
        for row in rows:
            t = time_lanes(kernels[row["variant"]], batches, scene, lim, a.repeat)
            row[f"ns_{threads}t"] = 1e9 * t / n
            row[f"shade_ns_{threads}t"] = 1e9 * t_shade / n
            print(f"  {row['variant']:>18}: {row[f'ns_{threads}t']:.1f} ns/vertex "
                  f"({t_shade / t:.1f}x shade)")
    if a.asm:
        for row in rows:
            row["asm"] = packed_counts(row["variant"], {})  # the child inherits NUMBA_CPU_FEATURES
            print(f"  {row['variant']:>18}: {row['asm']}")
    doc = {"scene": a.scene, "spp": a.spp, "width": a.width, "height": a.height, "vertices": n,
           "lanes": LANES, "slp_vectorize": bool(numba.config.SLP_VECTORIZE),
           "prefer_256_bit": "-prefer-256-bit" not in os.environ.get("NUMBA_CPU_FEATURES", ""), "cpu": _cpu_name(), "same_work": z,
           "variants": rows}
    os.makedirs(os.path.dirname(a.out), exist_ok=True)
    atomic.write_json(a.out, doc, indent=1)
    print(f"wrote {os.path.relpath(a.out)}")


def _cpu_name():
    m = re.search(r"^model name\s*:\s*(.*)$", _cpuinfo(), re.M)
    return m.group(1).strip() if m else ""


if __name__ == "__main__":
    main()
