"""tracer: a CPU path tracer for path-guiding research.

    scene = tracer.load_scene("scenes/cornell/cornell.obj", width=128, height=128)
    result = tracer.render(scene, spp=64)
    tracer.write_image("cornell.exr", result.image)
"""
import os as _os

# Numba's OpenMP workers keep their default wait policy: they spin for a short while after a
# parallel kernel, then sleep. The wavefront calls several kernels per bounce, milliseconds
# apart, and a worker that is still spinning starts the next one at once: on the Cornell box
# (2 cores) OMP_WAIT_POLICY=PASSIVE was 25% slower (median 1.3 against 1.64 Msamples/s, 8
# interleaved runs each), and ACTIVE, which spins forever, no faster than the default.
# No hot path uses BLAS; its idle worker threads would only compete for the two cores.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .errors import SceneError, SettingsError, TracerError
from .imageio import read_image, write_image
from .provenance import __version__
from .render import RenderResult, render, write_outputs
from .scene import load_scene

__all__ = ["load_scene", "render", "write_image", "read_image", "write_outputs", "RenderResult",
           "TracerError", "SceneError", "SettingsError"]
