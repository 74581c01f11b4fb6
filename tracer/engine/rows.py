"""The lanes' state, declared once: the rows of the float32 and int32 matrices that hold a wave's
paths ([row, lane]), a bounce's flags and shadow rays, and the scene's columns per triangle. The
kernels of tracer.engine.lanes and tracer.engine.general index rows by these names; LaneBuffers
allocates from the tuples, and compaction and splitting copy every row of them."""
import numpy as np

# The lane state, declared once: rows of the float32 and int32 matrices. The ray (origin relative
# to the accel's centre, unit direction), the throughput, the radiance so far, the density of the
# last sampled direction; the wave's path slot, the bounces so far, the 32-bit key, whether the
# last direction came from a delta lobe (or the camera).
FLOAT_ROWS = ("ox", "oy", "oz", "dx", "dy", "dz", "br", "bg", "bb", "lr", "lg", "lb", "pdf")
INT_ROWS = ("slot", "depth", "key", "delta")
OX, OY, OZ, DX, DY, DZ, BR, BG, BB, LR, LG, LB, PDF = range(len(FLOAT_ROWS))
SLOT, DEPTH, KEY, DELTA = range(len(INT_ROWS))
# A bounce's flags (int32): the path goes on, it has a shadow ray. (Whether the vertex is of the
# fast class is an array of its own, LaneBuffers.fast: the fast kernel reads it, and a loop that
# reads one row of an array and writes others is left scalar by LLVM.)
FLAG_ROWS = ("alive", "shadow")
ALIVE, SHADOW = range(len(FLAG_ROWS))
# A bounce's shadow rays: origin, unit direction, tmax, the value it adds if unblocked
SHADOW_ROWS = ("sox", "soy", "soz", "sdx", "sdy", "sdz", "tmax", "sr", "sg", "sb")
SOX, SOY, SOZ, SDX, SDY, SDZ, TMAX, SR, SG, SB = range(len(SHADOW_ROWS))
# A bounce's hit: its distance and barycentrics
HIT_ROWS = ("t", "b1", "b2")
H_T, H_B1, H_B2 = range(len(HIT_ROWS))
# The scene's columns per triangle (lanes.LaneScene: geo[triangle, column], tl[triangle, column]):
# geo (the corner v0, the edges e1, e2, the geometric normal, the corner normals vn0, vn1, vn2:
# three columns each; in a scene where some classed triangle is textured, the corner UVs u0 v0 u1
# v1 u2 v2) and tl (NEE's probability of choosing it, its area, its ray offset, 1 if one-sided, its
# vertices' class (lanes.fast_triangles), its colour's texture (-1: none), its colour and its
# emitted radiance, three columns each)
G_V0, G_E1, G_E2, G_N, G_VN, G_UV = 0, 3, 6, 9, 12, 21
TL_SEL, TL_AREA, TL_EPS, TL_ONE_SIDED, TL_FAST, TL_TEX, TL_KD, TL_EMIT = 0, 1, 2, 3, 4, 5, 6, 9
TL_ROWS = 12

# lim, the int32 settings the lanes' kernels take: rr_depth, max_depth (< 0: none), nee, the
# emissive triangles' count, whether the scene has corner normals
L_RR, L_MAX, L_NEE, L_LIGHTS, L_SMOOTH = range(5)

# Rows are this many lanes longer than they need be: rows a power of two long lie a multiple of
# 4 KiB apart, and a loop that touches 13 of them at once then maps them to the same cache sets
# (measured on the start kernel: 27 ns a lane unpadded, 5 ns padded)
PAD = 16


def _rows(rows, n, dtype):
    """(rows, n + PAD) zeros: rows for n lanes, a padded stride apart (PAD)."""
    return np.zeros((rows, n + PAD), dtype)
