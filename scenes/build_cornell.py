"""Writes scenes/cornell/cornell.{obj,mtl,json}: the classic Cornell box.

Geometry from the Cornell University measurements (millimetres, here in metres), with
the RGB reflectances commonly used for it (white 0.725 0.71 0.68, red 0.63 0.065 0.05,
green 0.14 0.45 0.091) and an emitter of radiance (17, 12, 4) just below the ceiling,
facing down. Run: `python scenes/build_cornell.py`.
"""
import json
import os

QUADS = {
    "floor": ("white", [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)]),
    "ceiling": ("white", [(556, 548.8, 0), (556, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)]),
    "back": ("white", [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2)]),
    "right": ("green", [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)]),
    "left": ("red", [(552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0)]),
    # The emitter sits 0.1 mm below the ceiling so the two never overlap; CCW normal is -y.
    "light": ("light", [(343, 548.7, 227), (343, 548.7, 332), (213, 548.7, 332), (213, 548.7, 227)]),
}
BLOCKS = {
    "short": [[(130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)],
              [(290, 0, 114), (290, 165, 114), (240, 165, 272), (240, 0, 272)],
              [(130, 0, 65), (130, 165, 65), (290, 165, 114), (290, 0, 114)],
              [(82, 0, 225), (82, 165, 225), (130, 165, 65), (130, 0, 65)],
              [(240, 0, 272), (240, 165, 272), (82, 165, 225), (82, 0, 225)]],
    "tall": [[(423, 330, 247), (265, 330, 296), (314, 330, 456), (472, 330, 406)],
             [(423, 0, 247), (423, 330, 247), (472, 330, 406), (472, 0, 406)],
             [(472, 0, 406), (472, 330, 406), (314, 330, 456), (314, 0, 456)],
             [(314, 0, 456), (314, 330, 456), (265, 330, 296), (265, 0, 296)],
             [(265, 0, 296), (265, 330, 296), (423, 330, 247), (423, 0, 247)]],
}
MTL = """# Cornell box materials (Kd Lambertian, Ke emission)
newmtl white
Kd 0.725 0.71 0.68

newmtl red
Kd 0.63 0.065 0.05

newmtl green
Kd 0.14 0.45 0.091

newmtl light
Kd 0 0 0
Ke 17 12 4
"""
SIDECAR = {
    "camera": {"origin": [0.278, 0.273, -0.8], "target": [0.278, 0.273, 0.0], "up": [0, 1, 0],
               "fov": 39.3077, "fov_axis": "x"},
    "film": {"width": 256, "height": 256},
    "render": {"spp": 64, "max_depth": -1, "rr_depth": 5, "seed": 0},
}


def main(folder=os.path.join(os.path.dirname(__file__), "cornell")):
    os.makedirs(folder, exist_ok=True)
    lines = ["# The Cornell box (Cornell University measurements, metres)", "mtllib cornell.mtl"]
    nv = 0
    groups = [(name, mat, [quad]) for name, (mat, quad) in QUADS.items()]
    groups += [(f"{name}_block", "white", quads) for name, quads in BLOCKS.items()]
    for name, mat, quads in groups:
        lines += [f"o {name}", f"usemtl {mat}"]
        for quad in quads:
            for x, y, z in quad:
                lines.append(f"v {x / 1000:.4f} {y / 1000:.4f} {z / 1000:.4f}")
            lines.append(f"f {nv + 1} {nv + 2} {nv + 3}")
            lines.append(f"f {nv + 1} {nv + 3} {nv + 4}")
            nv += 4
    with open(os.path.join(folder, "cornell.obj"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(folder, "cornell.mtl"), "w") as f:
        f.write(MTL)
    with open(os.path.join(folder, "cornell.json"), "w") as f:
        json.dump(SIDECAR, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
