"""The integrator seam: what render() and the Session ask of an integrator.

An integrator turns the render's final passes into an image. The method's schedule (a guide's
`schedule(session)`, or `session.final_passes()` without a guide) decides when the final passes
start; `session.final_passes` then asks the integrator for its film (`final_film`) and renders
each pass through it (`final_pass`), so a guide trains by its own schedule before any
integrator's passes. After the passes `result` makes the RenderResult.

A new integrator subclasses Integrator, sets `name` and `DEFAULTS` (every setting with its
default: the spec grammar of tracer.methods checks names against them), and registers in
tracer/integrators/__init__.py. docs/architecture.md walks through one.
"""
from ..errors import SettingsError
from ..methods import check_settings

# Seconds a time budget keeps back, beyond a post-pass step's own timed estimate, for a step that
# runs to its end (GradNet's inference, the denoiser): right after a budgeted render's last pass
# such a call took 0.025-0.045 s longer than the same call timed warm before the passes (96 x 96,
# both steps, the idle 2-core VM; the threads of the render's kernels still hold the cores).
AFTER_PASSES_SECONDS = 0.04


def flag(name, value):
    """A 0/1 setting as an int (bools accepted)."""
    if value not in (0, 1) or isinstance(value, float):
        raise SettingsError(f"integrator setting {name} must be 0 or 1, got {value!r}")
    return int(value)


class Integrator:
    """Base class of integrators. settings: {name: value} over DEFAULTS (unknown names: one error
    naming the valid ones); `given` keeps the settings passed explicitly."""

    name = "integrator"
    DEFAULTS = {"nee": 1}
    sweeps = 2  # samples every pixel of the final film gets before a pass may be cut at the deadline
    film_kind = "final"  # the kind of its final film in session.films (film.combine_films)
    outputs = ()  # result.buffers written beside the image as <name>.<buffer>.exr (render.write_outputs)

    def __init__(self, **settings):
        self.given = dict(settings)
        self.settings = check_settings("integrator", self.name, settings, self.DEFAULTS)
        self.nee = bool(flag("nee", self.settings["nee"]))

    # before the render
    def start(self):
        """Called by render() before its passes: forget any earlier render's state."""

    def check_guide(self, guide, guide_name):
        """SettingsError if this integrator cannot run with `guide` (a Guide, or None)."""

    def wave_bytes(self, wave):
        """Bytes of wave buffers beyond the path tracer's WaveBuffers for waves of `wave` paths."""
        return 0

    def memory(self):
        """(bytes per film pixel, fixed bytes) the integrator holds (tracer.memory)."""
        from .. import memory

        return memory.PATH_PIXEL_BYTES, 0

    def warm_up(self, ctx):
        """Compile (or load from the cache) this integrator's kernels beyond the path tracer's."""

    def kernels(self):
        """The kernels its passes run ("module.function", as _jit.kernels_cached takes them):
        the path tracer's per-thread loop by default."""
        return ("thread_loop.trace_paths",)

    def reserve(self, width, height):
        """Seconds of a time budget to keep for the work after the passes (e.g. a solve)."""
        return 0.0

    def stats_settings(self):
        """The settings as the render's stats record them."""
        return {"integrator": self.name, **self.settings}

    # the passes
    def final_film(self, session):
        """The film the final passes render into (what session.final_passes watches)."""
        return session.final

    def final_pass(self, session, film, spp, split=None, source=None):
        """Render one final pass of `spp` samples per pixel into `film` (deadline-cut)."""
        session.run_pass(film, spp, "final", source=source, split=split, deadline=True)

    def result(self, session, interrupted, snapshot):
        """The RenderResult after the passes; snapshot() gives the stats dict."""
        raise NotImplementedError

    def __repr__(self):
        return f"{type(self).__name__}({self.settings})"
