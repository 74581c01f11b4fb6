"""Statistical checks of samplers and renders, for the tests and the benchmarks (the renderer
itself never imports this package): z-tests of estimates against expected values at
Sidak-corrected levels (stats.py: one `sidak`, one `z_critical`) and chi-square tests of direction
samplers against the densities they report (chi2.py, in the manner of Mitsuba 3's `chi2`)."""
from .chi2 import ChiSquareTest, histogram_test, pooled_chi2, sphere_grid  # noqa: F401
from .stats import ALPHA, assert_clean, assert_z, image_mean, sidak, z_critical  # noqa: F401
