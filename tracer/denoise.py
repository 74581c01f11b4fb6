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
    device and loading the network weights costs more than a small image's filter)."""

    _shared = {}

    @classmethod
    def shared(cls, threads=None, quality="high"):
        """One Denoiser per (threads, quality) for the process: what render() uses, so that a run of
        renders makes the device and times the filter once."""
        key = (threads, quality)
        if key not in cls._shared:
            cls._shared[key] = cls(threads, quality)
        return cls._shared[key]

    def __init__(self, threads=None, quality="high"):
        require(quality)
        import pyoidn

        self._seconds = {}

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

    def run_filter(self, images, hdr, what, clean_aux=True):
        """Run one RT filter over {slot: float32 (H, W, 3) array}, the output array among them;
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
            f.execute()
            self._check(what)
        finally:
            f.release()

    def __call__(self, image, albedo=None, normal=None):
        """The denoised (H, W, 3) float32 image. albedo (clipped to [0, 1]) and normal are the
        render's buffers (result.aovs), prefiltered first; normal needs albedo (OIDN's rule)."""
        color = _rgb(image, "image")
        shape = color.shape
        images = {"color": color}
        if normal is not None and albedo is None:
            raise SettingsError("denoise: a normal buffer needs an albedo buffer too (Open Image Denoise)")
        for slot, aux in (("albedo", albedo), ("normal", normal)):
            if aux is None:
                continue
            aux = _rgb(aux, slot)
            if aux.shape != shape:
                raise SettingsError(f"denoise: the {slot} buffer is {aux.shape}, the image {shape}")
            aux = np.clip(aux, 0.0, 1.0) if slot == "albedo" else np.clip(aux, -1.0, 1.0)
            clean = np.empty_like(aux)
            self.run_filter({slot: np.ascontiguousarray(aux), "output": clean}, False, f"prefiltering the {slot}")
            images[slot] = clean
        out = np.empty_like(color)
        images["output"] = out
        self.run_filter(images, True, "denoising the image")
        return out

    def close(self):
        self.device.release()


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
    result.stats["time_denoise"] = dt
    result.stats["time_total"] += dt
    result.stats["nonfinite_denoised"] = int(bad.sum())
    return result


def reserve_seconds(denoiser, width, height):
    """Seconds the denoiser takes on a width x height image (timed once per size on a blank one,
    after a first call that loads the weights): what a time budget keeps back for it."""
    if (width, height) not in denoiser._seconds:
        blank = np.zeros((height, width, 3), np.float32)
        denoiser(blank, blank, blank)
        t0 = time.perf_counter()
        denoiser(blank, blank, blank)
        denoiser._seconds[width, height] = time.perf_counter() - t0
    return denoiser._seconds[width, height]
