"""Writes tracer/data/sunsky_rgb.npz, the tables of tracer.sunsky, from Mitsuba 3's own data.

    python -m bench.sunsky_tables            # needs mitsuba==3.9.1 (pip install -e ".[mitsuba]")

Mitsuba 3's `sunsky` emitter (after Hosek and Wilkie 2012/2013, BSD-3 data, see its
data/sunsky/LICENSE) reads two tensor files. From them, in RGB:
- sky_params (turbidity 1..10, albedo 0/1, 6 Bezier control points over the sun's elevation,
  3 channels, 9 parameters) and sky_rad (the same without the parameter axis): copied as they are;
- sun_rgb (turbidity 1..10, sun elevation 2, 5, ..., 89 degrees, 3): the sun's RGB irradiance at
  normal incidence, sun_scale 1, read off the emitter itself (its radiance toward the sun's centre
  times the disc's solid angle; the irradiance does not depend on the disc's size), so that the
  spectral-to-RGB conversion is Mitsuba's own.
The file is written atomically beside a JSON manifest (source files' sha256, version, command).
"""
import hashlib
import json
import os
import sys

import numpy as np

from bench.atomic import write, write_text

OUT = os.path.join(os.path.dirname(__file__), "..", "tracer", "data", "sunsky_rgb.npz")
ELEVATIONS = 2.0 + 3.0 * np.arange(30)  # degrees: the grid of Mitsuba 3's irradiance tables
# The sun is read with a 20-degree aperture: Mitsuba 3 divides the irradiance by the disc's solid
# angle 2 pi (1 - cos a) in float32, which loses 0.2% at its default half-aperture of 0.27 degrees.
APERTURE = 20.0


def read_tensor_file(path):
    """{name: array} of a Mitsuba 3 tensor file: b"tensor_file\\0", u16 version, u32 field count, then
    per field u16 name length, name, u16 rank, u8 Dr.Jit type (10 float32, 11 float64), u64 offset,
    rank u64 sizes; the data little-endian at each offset."""
    raw = open(path, "rb").read()
    assert raw[:12] == b"tensor_file\0", path
    count = int.from_bytes(raw[14:18], "little")
    pos, out = 18, {}
    for _ in range(count):
        n = int.from_bytes(raw[pos:pos + 2], "little")
        name = raw[pos + 2:pos + 2 + n].decode()
        pos += 2 + n
        rank = int.from_bytes(raw[pos:pos + 2], "little")
        dtype = {10: "<f4", 11: "<f8"}[raw[pos + 2]]
        offset = int.from_bytes(raw[pos + 3:pos + 11], "little")
        shape = tuple(int.from_bytes(raw[pos + 11 + 8 * i:pos + 19 + 8 * i], "little") for i in range(rank))
        pos += 11 + 8 * rank
        out[name] = np.frombuffer(raw, dtype, int(np.prod(shape)), offset).reshape(shape).astype(np.float64)
    return out


def sun_rgb(mi, turbidity, elevation_deg):
    """Mitsuba 3's sun irradiance (RGB, W/m^2 in its units) at one grid node."""
    e = np.radians(elevation_deg)
    d = [float(np.cos(e)), 0.0, float(np.sin(e))]
    em = mi.load_dict({"type": "sunsky", "sun_direction": d, "turbidity": float(turbidity),
                       "sky_scale": 0.0, "sun_scale": 1.0, "sun_aperture": APERTURE})
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(-d[0], -d[1], -d[2])
    radiance = np.array(em.eval(si), dtype=np.float64)
    return radiance * 2.0 * np.pi * (1.0 - np.cos(np.radians(0.5 * APERTURE)))


def main(argv=None):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    folder = os.path.join(os.path.dirname(mi.__file__), "data", "sunsky")
    files = [os.path.join(folder, f) for f in ("sunsky_datasets.bin", "sampling_data.bin")]
    data = read_tensor_file(files[0])
    sky_params, sky_rad = data["sky_params_rgb"], data["sky_rad_rgb"]
    assert sky_params.shape == (10, 2, 6, 3, 9) and sky_rad.shape == (10, 2, 6, 3), (sky_params.shape, sky_rad.shape)
    sun = np.array([[sun_rgb(mi, t, e) for e in ELEVATIONS] for t in range(1, 11)])
    out = os.path.abspath(OUT)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    write(out, lambda tmp: np.savez(tmp, sky_params=sky_params, sky_rad=sky_rad, sun_rgb=sun,
                                    elevations=ELEVATIONS))
    manifest = {
        "what": "RGB tables of Mitsuba 3's sunsky emitter (Hosek-Wilkie sky and sun), read by tracer.sunsky",
        "command": "python -m bench.sunsky_tables",
        "mitsuba": mi.__version__,
        "sources": {os.path.basename(f): hashlib.sha256(open(f, "rb").read()).hexdigest() for f in files},
        "license": "the data: Hosek and Wilkie's 3-clause BSD license (Mitsuba's data/sunsky/LICENSE)",
        "arrays": {"sky_params": list(sky_params.shape), "sky_rad": list(sky_rad.shape), "sun_rgb": list(sun.shape),
                   "elevations": list(ELEVATIONS.shape)},
    }
    write_text(out.replace(".npz", ".json"), json.dumps(manifest, indent=1) + "\n")
    print(f"wrote {out} ({os.path.getsize(out)} bytes); sun_rgb range {sun.min():.4g}..{sun.max():.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
