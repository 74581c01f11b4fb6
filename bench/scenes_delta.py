"""A small room lit by one delta light (`point`, `spot` or `directional`), in Mitsuba 3 XML, written on
demand, for bench.vs_mitsuba and tests/test_delta_lights.py.

    write(folder, kind, width=32, height=24) -> path of scene.xml
    python -m bench.vs_mitsuba delta --width 64 --height 48 --spp 64 --seeds 4   # or delta-spot, ...

The room: a 4 x 4 diffuse floor (y = 0, grey 0.6), a blue diffuse back wall (z = -1.2), a rough gold
cube (GGX alpha 0.2) turned 30 degrees; max_depth 4; the camera above the front edge looking down
at the cube. The lights:

    point        at (-0.3, 1.1, 0.4), intensity (3, 2, 1.5)
    spot         at (-0.2, 1.6, 0.8) aimed at (0.1, 0, -0.2) by a lookat, intensity (9, 7, 5),
                 cutoff 35 and beam 18 degrees: the ring between them lies on the floor in view
    directional  travelling along (-0.3, -1, -0.45), irradiance (1.5, 1.3, 1): the open room is lit
                 from above and the cube's shadow falls on the floor and wall
    spot-texture the spot projecting slide.png (slide(): 6 x 4 random colours) across its cone
"""
import os

from . import atomic

KINDS = ("point", "spot", "directional", "spot-texture")
FOLDER = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench", "results", "scenes")

CAMERA = """<sensor type="perspective"><float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0, 1.6, 3.2" target="0, 0.3, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/>
            <rfilter type="box"/></film>
    </sensor>"""
ROOM = """<integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <shape type="rectangle"><transform name="to_world"><scale value="2"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="2"/><translate z="-1.2"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>
    <shape type="cube"><transform name="to_world"><scale value="0.3"/><rotate y="1" angle="30"/>
        <translate x="0.4" y="0.3" z="-0.2"/></transform>
        <bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.2"/></bsdf>
    </shape>"""
LIGHTS = {
    "point": """<emitter type="point"><point name="position" x="-0.3" y="1.1" z="0.4"/>
        <rgb name="intensity" value="3, 2, 1.5"/></emitter>""",
    "spot": """<emitter type="spot"><transform name="to_world"><lookat origin="-0.2, 1.6, 0.8" target="0.1, 0, -0.2"
        up="0, 1, 0"/></transform><rgb name="intensity" value="9, 7, 5"/><float name="cutoff_angle" value="35"/>
        <float name="beam_width" value="18"/></emitter>""",
    "directional": """<emitter type="directional"><vector name="direction" x="-0.3" y="-1" z="-0.45"/>
        <rgb name="irradiance" value="1.5, 1.3, 1"/></emitter>""",
    "spot-texture": """<emitter type="spot"><transform name="to_world"><lookat origin="-0.2, 1.6, 0.8"
        target="0.1, 0, -0.2" up="0, 1, 0"/></transform><rgb name="intensity" value="9, 7, 5"/>
        <float name="cutoff_angle" value="35"/><float name="beam_width" value="18"/>
        <texture type="bitmap" name="texture"><string name="filename" value="slide.png"/></texture></emitter>""",
}


def slide():
    """(4, 6, 3) the textured spot's image, linear: random colours (seed 5), coarse enough that each
    texel covers a patch of the floor; written as an 8-bit sRGB PNG, which both renderers decode."""
    import numpy as np

    return np.random.default_rng(5).uniform(0.05, 1.0, size=(4, 6, 3))


def xml(body, width=32, height=24):
    """A scene file's text: the camera at width x height and `body` (shapes, emitters)."""
    return f'<scene version="3.0.0">\n    {CAMERA.format(w=width, h=height)}\n    {body}\n</scene>\n'


def write(folder, kind, width=32, height=24, name="scene.xml"):
    """The room lit by light `kind` (KINDS) as folder/name; its path."""
    if kind not in LIGHTS:
        raise ValueError(f"no delta-light scene {kind!r}; valid: {', '.join(KINDS)}")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, name)
    if kind == "spot-texture":
        from tracer.imageio import write_image

        write_image(os.path.join(folder, "slide.png"), slide())
    text = xml(ROOM + LIGHTS[kind], width, height)
    atomic.write(path, lambda tmp: open(tmp, "w").write(text))
    return path


def scene(kind, **kw):
    """write() into bench/results/scenes/delta-<kind>; the path of its scene.xml."""
    return write(os.path.join(FOLDER, f"delta-{kind}"), kind, **kw)
