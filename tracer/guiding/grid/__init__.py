"""The histogram guides on a hierarchical grid (Zhu et al. 2021): `grid` (maps from camera paths)
and `photon` (maps from photons) in guides.py; the grid itself (spatial.py), the photon tracer
(photons.py), the map reconstructions (reconstruct.py, the CNN in photon_cnn.py) and their
schedule, Algorithm 1 (schedule.py)."""
