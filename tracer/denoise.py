"""Intel Open Image Denoise (OIDN, the `pyoidn` package: `pip install -e ".[denoise]"`) on a
finished render, guided by its albedo and normal buffers.

As OIDN's documentation recommends for noisy auxiliary buffers, the albedo and the normal are
first denoised on their own by the RT filter ("prefiltered"), then the colour is denoised with
them and `cleanAux` set; `hdr` is on (radiance is not bounded by 1). The filters run on OIDN's CPU
device with the render's thread count.

    from tracer.denoise import denoise
    clean = denoise(result.image, result.aovs["albedo"], result.aovs["normal"])

render(..., denoise=True) does this after the passes (result.denoised, stats time_denoise), with
the denoiser's time kept out of a time budget's passes; the CLI's --denoise writes the result as
<name>.denoised.exr and its PNG.
"""
import time

import numpy as np

from .errors import SettingsError

QUALITIES = ("high", "balanced", "fast")
INSTALL = 'pip install -e ".[denoise]"'


def available():
    """Whether pyoidn (OIDN's Python binding) can be imported."""
    try:
        import pyoidn  # noqa: F401
    except ImportError:
        return False
    return True


def require(quality="high"):
    """SettingsError, one line, if denoising cannot run: pyoidn missing, or an unknown quality."""
    if quality not in QUALITIES:
        raise SettingsError(f"denoise quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
    if not available():
        raise SettingsError(f"denoising needs Intel Open Image Denoise (the pyoidn package): {INSTALL}")


class Denoiser:
    """An OIDN CPU device with `threads` threads; call it as denoise() (reuse it: creating the
    device and loading the network weights costs more than a small image's filter).

    The filters of a call (the albedo's and the normal's prefilter, the colour filter) are built
    and committed once per image size and set of buffers, bound to arrays the Denoiser keeps,
    and only executed by later calls of that size (building them costs several times the filter
    itself); the last MAX_SIZES sizes are kept. `filters_built` counts the filters built. Calls
    run one at a time (a lock)."""

    MAX_SIZES = 4
    _shared = {}

    @classmethod
    def shared(cls, threads=None, quality="high"):
        """One Denoiser per (threads, quality) for the process: what render() uses, so that a run of
        renders makes the device, builds the filters and times them once per image size."""
        key = (threads, quality)
        if key not in cls._shared:
            cls._shared[key] = cls(threads, quality)
        return cls._shared[key]

    def __init__(self, threads=None, quality="high"):
        require(quality)
        import threading

        import pyoidn

        self._seconds = {}
        # (width, height) -> seconds the last call after a render's passes took (apply): what the
        # next budget at that size keeps back for it
        self.after_passes = {}
        self._prepared = {}  # (height, width, albedo given, normal given) -> _Prepared, oldest first
        self._lock = threading.Lock()
        self.filters_built = 0

        self._oidn = pyoidn
        self.quality = {"high": pyoidn.OIDN_QUALITY_HIGH, "balanced": pyoidn.OIDN_QUALITY_BALANCED,
                        "fast": pyoidn.OIDN_QUALITY_FAST}[quality]
        self.device = pyoidn.Device()
        if threads:
            self.device.set_int("numThreads", int(threads))
        self.device.commit()
        self._check("creating the CPU device")

    def _check(self, what):
        err = self.device.get_error()
        if err:
            raise RuntimeError(f"Open Image Denoise failed {what}: {err}")

    def _new_filter(self, images, hdr, what, clean_aux=True):
        """A committed RT filter bound to {slot: float32 (H, W, 3) array} (the output among them);
        hdr: the colour filter (with cleanAux: the buffers were prefiltered), else a prefilter."""
        o = self._oidn
        f = o.Filter(self.device, "RT")
        try:
            for slot, arr in images.items():
                f.set_image(slot, arr, o.OIDN_FORMAT_FLOAT3)
            if hdr:
                f.set_bool("hdr", True)
                f.set_bool("cleanAux", clean_aux)
            f.set_quality(self.quality)
            f.commit()
            self._check(what)
        except BaseException:
            f.release()
            raise
        self.filters_built += 1
        return f

    def run_filter(self, images, hdr, what, clean_aux=True):
        """Build, run and release one RT filter over {slot: float32 (H, W, 3) array}, the output
        array among them (for experiments with other inputs; __call__ keeps its filters)."""
        f = self._new_filter(images, hdr, what, clean_aux)
        try:
            f.execute()
            self._check(what)
        finally:
            f.release()

    def _filters_for(self, shape, slots):
        """The _Prepared of images of `shape` with the auxiliary buffers `slots`, built on first use."""
        key = (shape[0], shape[1]) + tuple(s in slots for s in ("albedo", "normal"))
        prepared = self._prepared.pop(key, None)
        if prepared is None:
            prepared = _Prepared(self, shape, slots)
            while len(self._prepared) >= self.MAX_SIZES:
                self._prepared.pop(next(iter(self._prepared))).release()
        self._prepared[key] = prepared  # (re)inserted last: the most recently used
        return prepared

    def __call__(self, image, albedo=None, normal=None):
        """The denoised (H, W, 3) float32 image. albedo (clipped to [0, 1]) and normal are the
        render's buffers (result.aovs), prefiltered first; normal needs albedo (OIDN's rule)."""
        color = _rgb(image, "image")
        shape = color.shape
        if normal is not None and albedo is None:
            raise SettingsError("denoise: a normal buffer needs an albedo buffer too (Open Image Denoise)")
        aux = {}
        for slot, a in (("albedo", albedo), ("normal", normal)):
            if a is None:
                continue
            a = _rgb(a, slot)
            if a.shape != shape:
                raise SettingsError(f"denoise: the {slot} buffer is {a.shape}, the image {shape}")
            aux[slot] = np.clip(a, 0.0, 1.0) if slot == "albedo" else np.clip(a, -1.0, 1.0)
        with self._lock:
            prepared = self._filters_for(shape, tuple(aux))
            return prepared.run(color, aux)

    def close(self):
        for prepared in self._prepared.values():
            prepared.release()
        self._prepared = {}
        self.device.release()


class _Prepared:
    """The committed filters of one image size and set of auxiliary buffers, with the arrays they
    are bound to: each auxiliary buffer's prefilter (into `<slot>_clean`), then the colour filter
    reading the prefiltered buffers."""

    def __init__(self, denoiser, shape, slots):
        self.images = {name: np.zeros(shape, np.float32)
                       for name in ("color", "output") + slots + tuple(s + "_clean" for s in slots)}
        im = self.images
        self.filters = []
        try:
            for slot in slots:
                what = f"prefiltering the {slot}"
                self.filters.append((denoiser._new_filter({slot: im[slot], "output": im[slot + "_clean"]}, False,
                                                          what), what))
            what = "denoising the image"
            colour = {"color": im["color"], "output": im["output"], **{s: im[s + "_clean"] for s in slots}}
            self.filters.append((denoiser._new_filter(colour, True, what), what))
        except BaseException:
            self.release()
            raise
        self._check = denoiser._check

    def run(self, color, aux):
        """Copy the inputs into the bound arrays, execute the filters in order; a copy of the output."""
        im = self.images
        np.copyto(im["color"], color)
        for slot, a in aux.items():
            np.copyto(im[slot], a)
        for f, what in self.filters:
            f.execute()
            self._check(what)
        return im["output"].copy()

    def release(self):
        for f, _ in self.filters:
            f.release()
        self.filters = []


def _rgb(a, what):
    """A contiguous float32 (H, W, 3) copy of `a` with non-finite values set to 0."""
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[2] < 3:
        raise SettingsError(f"denoise: the {what} must be (H, W, 3), got {a.shape}")
    a = np.ascontiguousarray(a[:, :, :3], dtype=np.float32)
    return np.where(np.isfinite(a), a, np.float32(0.0))


def denoise(image, albedo=None, normal=None, threads=None, quality="high"):
    """The denoised (H, W, 3) float32 image of `image`, guided by the albedo and normal buffers
    (tracer.RenderResult.aovs), on a device made for this call (see Denoiser to reuse one)."""
    d = Denoiser(threads, quality)
    try:
        return d(image, albedo, normal)
    finally:
        d.close()


def apply(result, denoiser):
    """Denoise a RenderResult in place: result.denoised, and in its stats time_denoise (seconds,
    added to time_total) and nonfinite_denoised (pixels that came out of the filter non-finite:
    they keep the raw image's value; never expected, so tests assert 0)."""
    t0 = time.perf_counter()
    out = denoiser(result.image, result.aovs["albedo"], result.aovs["normal"])
    bad = ~np.isfinite(out).all(axis=2)
    if bad.any():
        out[bad] = result.image[bad]
    result.denoised = out
    dt = time.perf_counter() - t0
    denoiser.after_passes[result.image.shape[1], result.image.shape[0]] = dt
    result.stats["time_denoise"] = dt
    result.stats["time_total"] += dt
    result.stats["nonfinite_denoised"] = int(bad.sum())
    return result


def reserve_seconds(denoiser, width, height, calls=3):
    """Seconds the denoiser takes on a width x height image: the slowest of `calls` timed calls on
    a blank one (after a first that builds the filters), timed once per size; what a time budget
    keeps back for it. (One call's time varies by 15% from run to run on a 2-core VM, and the
    budget's 1% cannot absorb that at a denoise of half the budget: the slowest keeps a render
    within its budget at the cost of a little time unused.)"""
    if (width, height) not in denoiser._seconds:
        blank = np.zeros((height, width, 3), np.float32)
        denoiser(blank, blank, blank)
        times = []
        for _ in range(int(calls)):
            t0 = time.perf_counter()
            denoiser(blank, blank, blank)
            times.append(time.perf_counter() - t0)
        denoiser._seconds[width, height] = max(times)
    return denoiser._seconds[width, height]
