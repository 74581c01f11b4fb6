"""Write a variant of the shared Mitsuba Cornell box whose walls use Mitsuba's plastics (and, with
--mask, an opacity mask), for bench.vs_mitsuba:

    python -m bench.coated_cornell ../shared/scenes-mitsuba/cornell-box/scene.xml /tmp/cb/scene.xml
    python -m bench.vs_mitsuba /tmp/cb/scene.xml --width 128 --height 128 --spp 512 --seeds 4

Floor: smooth `plastic` (index 1.5); back wall: GGX `roughplastic` (alpha 0.15, nonlinear); left
wall: Beckmann `roughplastic` (alpha 0.3); `--swap` picks which (and `mask` makes the right wall a
`mask` of opacity 0.6 around its diffuse). The two boxes (`cube` shapes, which the reader does not read yet) are left out
of both renders. The scene itself is read from ../shared and only rewritten to the output path.
"""
import argparse
import os
import re

SWAPS = {  # --swap name: (BSDF id, its replacement)
    "floor": "FloorBSDF",
    "back": "BackWallBSDF",
    "left": "LeftWallBSDF",
    "mask": "RightWallBSDF",
}
BODIES = {
    "FloorBSDF": '<bsdf type="twosided" id="FloorBSDF"><bsdf type="plastic">'
                 '<rgb name="diffuse_reflectance" value="0.6, 0.6, 0.55"/><float name="int_ior" value="1.5"/>'
                 '</bsdf></bsdf>',
    "BackWallBSDF": '<bsdf type="twosided" id="BackWallBSDF"><bsdf type="roughplastic">'
                    '<rgb name="diffuse_reflectance" value="0.7, 0.6, 0.5"/><float name="alpha" value="0.15"/>'
                    '<string name="distribution" value="ggx"/><boolean name="nonlinear" value="true"/></bsdf></bsdf>',
    "LeftWallBSDF": '<bsdf type="twosided" id="LeftWallBSDF"><bsdf type="roughplastic">'
                    '<rgb name="diffuse_reflectance" value="0.63, 0.065, 0.05"/><float name="alpha" value="0.3"/>'
                    '<string name="distribution" value="beckmann"/></bsdf></bsdf>',
}
BODIES["RightWallBSDF"] = ('<bsdf type="mask" id="RightWallBSDF"><float name="opacity" value="0.6"/><bsdf type="twosided">'
        '<bsdf type="diffuse"><rgb name="reflectance" value="0.14, 0.45, 0.091"/></bsdf></bsdf></bsdf>')


def variant(text, swaps=("floor", "back", "left")):
    """The Cornell box XML text with the named walls swapped (and the cubes dropped)."""
    for name in swaps:
        bid, body = SWAPS[name], BODIES[SWAPS[name]]
        text, n = re.subn(r'<bsdf type="twosided" id="%s">.*?</bsdf>\s*</bsdf>' % bid, body, text, flags=re.S)
        if n != 1:
            raise SystemExit(f"no BSDF {bid} to replace: is this the shared cornell-box/scene.xml?")
    return re.sub(r'<shape type="cube".*?</shape>', "", text, flags=re.S)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", help="the shared cornell-box/scene.xml")
    ap.add_argument("out", help="where to write the variant")
    ap.add_argument("--swap", default="floor,back,left",
                    help="walls to swap, comma-separated from floor, back, left, mask (default: the three plastics)")
    a = ap.parse_args(argv)
    swaps = [w for w in a.swap.split(",") if w]
    bad = [w for w in swaps if w not in SWAPS]
    if bad:
        ap.error(f"--swap: unknown {', '.join(bad)}; valid: {', '.join(SWAPS)}")
    text = variant(open(a.scene, encoding="utf-8").read(), swaps)
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    tmp = a.out + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, a.out)
    print(a.out)


if __name__ == "__main__":
    main()
