"""`odis`: per-pixel first-bounce maps from one network over an initial pass (Bako et al. 2019): the
guide (guide.py), the network's input gathered from the initial samples (features.py), the network
(net.py)."""
