"""The memory a render will need, estimated before anything is allocated, against what the machine has.

render() calls `check(...)` before it builds anything: a film the machine cannot hold fails at
once with one line that says how much the render needs and how much is available, instead of a
traceback from numpy after minutes, or the kernel's out-of-memory killer.

The estimate is per film pixel (the crop's pixels) plus what does not grow with the image:

- per pixel: the final film and the result (image, variance, AOVs, the combination of the
  passes' films and the writing of the outputs): PATH_PIXEL_BYTES, or GPT_PIXEL_BYTES[recon] for
  gradient-domain renders (five films, the buffers, the solve or the network); plus what the
  method holds beyond them (`Guide.pixel_bytes`: the films of its training passes, per-pixel
  maps);
- fixed: the wave buffers (bytes per path, measured on the buffer classes themselves), the ray
  accel and light tables (ACCEL_BYTES_PER_TRIANGLE), an environment map's sampling tables
  (ENV_BYTES_PER_TEXEL; the map itself is held by the loaded scene) and the method's own
  (`Guide.fixed_bytes`).

The per-pixel figures are the peak resident memory measured by `python -m bench.memory` (the
slope of peak RSS between two image sizes; docs/throughput.md) rounded up by about 25%;
tests/test_memory.py checks that the estimate stays above the measured peak of every method.
"""
import os

from .errors import SettingsError

PATH_PIXEL_BYTES = 280  # measured 219 B/px (bsdf, bench.memory)
GPT_PIXEL_BYTES = {"l1": 900, "l2": 900, "none": 900, "gradnet": 2400}  # RSS 462-483 and 1732 (traced: 700);
# gradnet_v2's weights 1897
GPT_FIXED_BYTES = {"gradnet": 256 << 20}  # torch and the network (measured about 190 MB)
ACCEL_BYTES_PER_TRIANGLE = 512  # measured 416: Embree's BVH and float32 vertices, normals, offsets
ENV_BYTES_PER_TEXEL = 40  # measured 32 (lights.build_lights' tables and their temporaries, tracemalloc)
HEADROOM = 0.9  # refuse a render that needs more than this share of the available memory


def _read_int(path):
    try:
        with open(path, encoding="ascii") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def available_bytes():
    """Memory a new allocation can get without swapping: MemAvailable from /proc/meminfo (Linux),
    else the physical memory (os.sysconf), else None (unknown: no check); within a cgroup v2
    memory limit (a container's), at most the limit less what the cgroup uses."""
    have = None
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    have = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if have is None:
        try:
            have = int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            return None
    limit, used = _read_int("/sys/fs/cgroup/memory.max"), _read_int("/sys/fs/cgroup/memory.current")
    if limit is not None and used is not None:  # ("max", no limit, reads as None)
        have = min(have, max(limit - used, 0))
    return have


def estimate(pixels, triangles, wave_bytes, guide=None, integrator=None, env_texels=0):
    """{"per_pixel", "fixed", "total"} bytes of a render of `pixels` film pixels over `triangles`
    triangles and an environment map of `env_texels` texels (0: none), with wave buffers of
    `wave_bytes`, by `guide` (a Guide, or None) and `integrator` (an integrators.base.Integrator:
    its memory(); None: the path tracer's)."""
    per_pixel, fixed = integrator.memory() if integrator is not None else (PATH_PIXEL_BYTES, 0)
    fixed += int(wave_bytes) + triangles * ACCEL_BYTES_PER_TRIANGLE + int(env_texels) * ENV_BYTES_PER_TEXEL
    if guide is not None:
        per_pixel += guide.pixel_bytes
        fixed += guide.fixed_bytes
    return {"per_pixel": per_pixel, "fixed": fixed, "total": pixels * per_pixel + fixed}


def _gib(b):
    if b >= 2**40:
        return f"{b / 2**40:.1f} TiB"
    return f"{b / 2**30:.1f} GiB" if b >= 2**30 else f"{b / 2**20:.0f} MiB"


def check(width, height, est, available=None):
    """SettingsError if the estimate `est` (estimate()) of a width x height film is more than
    HEADROOM of the available memory (available_bytes() unless given): one line with the need,
    what is available and the largest square film that fits."""
    have = available_bytes() if available is None else available
    need = est["total"]
    if have is None or need <= HEADROOM * have:
        return
    side = int(max(0.0, (HEADROOM * have - est["fixed"]) / est["per_pixel"]) ** 0.5)
    fits = f"about {side}x{side} pixels would fit" if side > 0 else "not even the scene and the buffers fit"
    raise SettingsError(f"a {width}x{height} render needs about {_gib(need)} of memory ({est['per_pixel']} bytes a "
                        f"pixel); this machine has {_gib(have)} available ({fits})")
