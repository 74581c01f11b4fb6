"""Compile the gradient-domain tracer's kernels into Numba's cache (run by tests/conftest.py in a
process of its own, on the second core, while the rest of the suite runs): a tiny gpt render of
each reconstruction that the suite's gpt tests compile for."""
import os

import tracer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    scene = tracer.load_scene(os.path.join(ROOT, "scenes", "cornell", "cornell.obj"), width=8, height=8)
    for recon in ("l1", "l2"):
        tracer.render(scene, spp=2, integrator="gpt", recon=recon, seed=1)


if __name__ == "__main__":
    main()
