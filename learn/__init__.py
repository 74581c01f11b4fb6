"""Offline learning for the renderer's networks: procedural scenes, Dask dataset shards, training
loops that checkpoint and resume, export of weights and manifests into tracer/weights. `tracer`
never imports this package. Entry points: `python -m learn.photon` (the photon map network).
"""
