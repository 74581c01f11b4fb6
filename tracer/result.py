"""What a render returns (RenderResult), and the check every finished image gets (report_dark)."""
import logging
import os
from dataclasses import dataclass, field

import numpy as np

from .film import Film

log = logging.getLogger("tracer")


@dataclass
class RenderResult:
    """image (H,W,3) float32 mean radiance; variance (H,W,3) float32 variance of that mean;
    aovs {albedo (H,W,3) at the first vertex that is not a delta BSDF, normal (H,W,3) and depth
    (H,W,1) at the first hit} float32; stats (dict, JSON-ready)."""

    image: np.ndarray
    variance: np.ndarray
    aovs: dict
    stats: dict
    film: Film = field(repr=False)
    buffers: dict = field(default_factory=dict, repr=False)  # integrator gpt: base, dx, dy, ... (see render())
    denoised: np.ndarray = field(default=None, repr=False)  # render(denoise=True): the image denoised (OIDN)

    def __repr__(self):
        s = self.stats
        return (f"RenderResult({self.image.shape[1]}x{self.image.shape[0]}, {s['spp']} spp, "
                f"{s['time_total']:.2f} s, {s['msamples_per_s']:.2f} Msamples/s)")


DARK_SHARE = 0.01  # a finished image with fewer lit pixels than this is reported


def report_dark(scene, image, stats):
    """stats["lit_share"]: the share of pixels whose luminance is above zero; a warning on the
    'tracer' logger, with the likely cause, when it is below DARK_SHARE."""
    from .framing import lit_share

    share = stats["lit_share"] = lit_share(image)
    if share >= DARK_SHARE or stats["samples"] == 0:
        return
    what = "the image is black: no path reached a light" if share == 0.0 else \
        f"only {share:.2%} of the pixels received light"
    sidecar = os.path.splitext(scene.path)[0] + ".json"
    if scene.framing:
        cause = (f"the scene gives no camera and the framed view ({scene.framing}) sees little light; "
                 f"give camera.origin and camera.target in {sidecar}")
    elif stats["max_depth"] == 1:
        cause = "max depth 1 shows only the emitters the camera sees directly"
    else:
        cause = (f"the camera ({sidecar}) may look past the scene or at the backs of walls, or the lights may face "
                 "away (an MTL Ke emits from the counter-clockwise side only)")
    log.warning(f"{scene.path}: {what}; {cause}")
