"""Network layers and helpers the learned parts share (the photon guide's map CNN, ODIS's network,
GradNet): convolutions on the sphere of directions (phi wraps around, z = cos(theta) repeats its
pole rows), partial convolutions (Liu et al. 2018), the inner levels of the map U-Nets, parameter
and operation counts, and loading shipped weights with their manifest. torch is imported here,
so only by the parts that use a network."""
import json
import os

import torch
import torch.nn.functional as F
from torch import nn

WEIGHTS_DIR = os.path.join(os.path.dirname(__file__), "weights")


def pad_sphere(x):
    """Pad by one bin: phi (last axis) wraps, z (rows) repeats the pole row."""
    x = F.pad(x, (1, 1, 0, 0), mode="circular")
    return F.pad(x, (0, 0, 1, 1), mode="replicate")


class PartialConv(nn.Module):
    """3x3 partial convolution: sum over the window's bins with data, rescaled by 9 / their number;
    returns the features and the new mask (1 where the window held any data)."""

    def __init__(self, cin, cout, stride=1):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, 3, stride=stride, bias=True)
        self.stride = stride
        self.register_buffer("ones", torch.ones(1, 1, 3, 3))

    def forward(self, x, m):
        xp, mp = pad_sphere(x * m), pad_sphere(m)
        cover = F.conv2d(mp, self.ones, stride=self.stride)
        out = F.conv2d(xp, self.conv.weight, None, stride=self.stride)
        has = (cover > 0).to(x.dtype)
        out = out * (9.0 / cover.clamp(min=1.0)) * has + self.conv.bias.view(1, -1, 1, 1)
        return out, has


class Conv(nn.Module):
    def __init__(self, cin, cout, stride=1):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, 3, stride=stride)

    def forward(self, x):
        return self.conv(pad_sphere(x))


def act(x):
    return F.leaky_relu(x, 0.1)


def inner_levels(net, e1):
    """The 1/2 and 1/4 levels of guiding.grid.photon_cnn.PhotonUNet and
    guiding.odis.net.OdisUNet, from the activated encoder
    features e1 at 1/2: a residual block (net.e1r), a strided convolution to 1/4 (net.e2) and a
    residual block (net.e2r), then upsampling with the skip link from e1 into net.d1 and a residual
    block (net.d1r). Returns (e1, e2, d1)."""
    e1 = e1 + act(net.e1r(e1))
    e2 = act(net.e2(e1))
    e2 = e2 + act(net.e2r(e2))
    d1 = act(net.d1(torch.cat([F.interpolate(e2, scale_factor=2, mode="nearest"), e1], 1)))
    d1 = d1 + act(net.d1r(d1))
    return e1, e2, d1


def parameter_count(model):
    return int(sum(p.numel() for p in model.parameters()))


def count_flops(model, run):
    """Floating-point operations (2 per multiply-add) of the convolutions (nn.Conv2d and
    nn.ConvTranspose2d modules and PartialConv) that `run()` performs with `model`."""
    total = []

    def conv_hook(mod, inp, out):  # nn.Conv2d called as a module (Conv, the heads)
        total.append(2 * out.numel() * mod.in_channels * mod.kernel_size[0] * mod.kernel_size[1])

    def transposed_hook(mod, inp, out):  # every input value meets out_channels x k x k weights
        total.append(2 * inp[0].numel() * mod.out_channels * mod.kernel_size[0] * mod.kernel_size[1])

    def partial_hook(mod, inp, out):  # PartialConv runs F.conv2d on its weight
        total.append(2 * out[0].numel() * mod.conv.in_channels * 9)

    hs = [m.register_forward_hook(conv_hook) for m in model.modules() if isinstance(m, nn.Conv2d)]
    hs += [m.register_forward_hook(transposed_hook) for m in model.modules() if isinstance(m, nn.ConvTranspose2d)]
    hs += [m.register_forward_hook(partial_hook) for m in model.modules() if isinstance(m, PartialConv)]
    with torch.inference_mode():
        run()
    for h in hs:
        h.remove()
    return int(sum(total))


def load_weights(build, name, folder, train_command):
    """(model in eval mode, manifest dict) of the weights `name`.pt / `name`.json in folder; build
    makes the module from the manifest's "model" settings."""
    path = os.path.join(folder, name + ".json")
    try:
        with open(path) as f:
            manifest = json.load(f)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no weights (train them with {train_command})") from None
    model = build(**manifest["model"])
    state = torch.load(os.path.join(folder, name + ".pt"), map_location="cpu", weights_only=True)
    model.load_state_dict(state)
    model.eval()
    return model, manifest
