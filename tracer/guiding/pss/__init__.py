"""`pss`: a Real NVP warp of primary sample space learned per scene at render time (Zheng and
Zwicker 2019): the guide, its training and the warped camera source (warp.py), the flow (flow.py)."""
