"""The render context: what a render's kernels, sources and guides read, gathered once.

A RenderContext is made by tracer.render() for one render and handed to the method
(`guide.prepare(scene, ctx)`), to every source (`source.start(ctx, ...)`) and to
integrators.path.trace_wave. Guides may read it; only the render writes `guide_state`.
"""
import numpy as np

from .bvh import ray_offsets
from .guiding.contract import empty_state
from .material import Surfaces


class RenderContext:
    """One render's fixed inputs.

    scene        the Scene (tracer.load_scene)
    accel        the ray-query accel (tracer.bvh.make_accel): intersect(o, d), occluded(o, d, tmax)
    lights       the light tables (tracer.lights.build_lights), a Numba-readable NamedTuple
    surfaces     material.Surfaces of the scene (with tri_normal and tri_eps below; its UVs,
                 vertex normals and textures), what material.surface_at reads
    tri_normal   (F, 3) float64 unit geometric normals; tri_eps (F,) float64 ray offsets, fitted to
                 the float32 coordinates the ray queries see there
    cam          the camera, packed for camera_ray
    seed         the render's seed (keys of camera paths and photons derive from it)
    max_depth, rr_depth   path depth limits (Mitsuba conventions, see tracer.integrators.path)
    nee          next-event estimation on (the integrator's `nee` setting; off: emission found by
                 a path counts in full, as in the guiding papers' equal-time tables)
    crop         (4,) int64 (x0, y0, w, h): the window of the image the film covers
    jitter       True for the box pixel filter, False for the point filter
    n_pixels     film pixels, w * h
    guide_state  the GuideState the kernels sample from (an empty one: BSDF sampling); set by the
                 render from guide.state() after each update
    path_loop    "thread": waves that record and split nothing run the per-thread path loop
                 (integrators.thread_loop; Embree only), "wave": every wave runs the wavefront
    """

    def __init__(self, scene, accel, lights, seed, max_depth, rr_depth, pixel_filter, crop, nee=True):
        self.scene, self.accel, self.lights = scene, accel, lights
        self.crop = np.asarray(crop, dtype=np.int64)
        self.jitter = pixel_filter == "box"
        tri = scene.tri
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.tri_normal = n / np.linalg.norm(n, axis=1, keepdims=True)
        self.cam = scene.camera.packed()
        self.seed = int(seed)
        self.max_depth = int(max_depth)
        self.rr_depth = int(rr_depth)
        self.nee = bool(nee)
        self.tri_eps = ray_offsets(tri, accel.centre)
        tex = scene.textures
        self.surfaces = Surfaces(tri, self.tri_normal, scene.tri_material, self.tri_eps, scene.materials.type,
                                 scene.materials.param, scene.tri_uv, scene.tri_vn, scene.materials.tex, tex.info,
                                 tex.data, scene.materials.table)
        self.n_pixels = int(self.crop[2] * self.crop[3])
        self.guide_state = empty_state()
        self.path_loop = "thread"

    def __repr__(self):
        x0, y0, w, h = (int(v) for v in self.crop)
        return (f"RenderContext({self.scene.path}, {w}x{h} at {x0},{y0}, seed {self.seed}, "
                f"max_depth {self.max_depth}, accel {self.accel.name})")
