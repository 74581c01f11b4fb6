"""The room of bench.scenes_delta lit by a `sunsky` emitter, in Mitsuba XML, written on demand, for
bench.vs_mitsuba and tests/test_sunsky.py.

    write(folder, variant, width=32, height=24) -> path of scene.xml
    python -m bench.vs_mitsuba sunsky --width 64 --height 48 --spp 64 --seeds 4   # or sunsky-hour, ...

Variants (the open room: the sky lights it from everywhere above, the sun casts the cube's shadow):

    direction  Mitsuba 3's names: sun_direction (0.5, 0.6, 0.35) in a +y-up world (to_world turns
               the emitter's +z up to +y), turbidity 4, ground albedo 0.5, sun_aperture 3 degrees,
               sky_scale 1.5
    hour       Mitsuba 3's names: the sun from a date, time and place (2010-07-10 8:30 in Tokyo, +y
               up: the sun in front of the back wall), turbidity 2.5, sun_aperture 4 degrees, sun_scale 0.8
    v06        0.6's names in a 0.6 file: sunDirection (-0.4, 0.5, 0.6), turbidity 6, skyScale 2,
               sunScale 0.7, sunRadiusScale 6 (a sun 3.2 degrees across), 0.6's default albedo 0.15
"""
import os

from . import atomic
from .scenes_delta import CAMERA, ROOM

VARIANTS = ("direction", "hour", "v06")
FOLDER = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench", "results", "scenes")

Y_UP = '<transform name="to_world"><rotate x="1" angle="-90"/></transform>'
EMITTERS = {
    "direction": f"""<emitter type="sunsky"><vector name="sun_direction" x="0.5" y="0.6" z="0.35"/>
        <float name="turbidity" value="4"/><rgb name="albedo" value="0.5"/><float name="sun_aperture" value="3"/>
        <float name="sky_scale" value="1.5"/>{Y_UP}</emitter>""",
    "hour": f"""<emitter type="sunsky"><integer name="year" value="2010"/><integer name="month" value="7"/>
        <integer name="day" value="10"/><float name="hour" value="8.5"/><float name="turbidity" value="2.5"/>
        <float name="sun_aperture" value="4"/><float name="sun_scale" value="0.8"/>{Y_UP}</emitter>""",
    "v06": """<emitter type="sunsky"><vector name="sunDirection" x="-0.4" y="0.5" z="0.6"/>
        <float name="turbidity" value="6"/><float name="skyScale" value="2"/><float name="sunScale" value="0.7"/>
        <float name="sunRadiusScale" value="6"/></emitter>""",
}


def write(folder, variant, width=32, height=24, name="scene.xml"):
    """The room lit by sunsky `variant` (VARIANTS) as folder/name; its path."""
    if variant not in EMITTERS:
        raise ValueError(f"no sunsky scene {variant!r}; valid: {', '.join(VARIANTS)}")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, name)
    version = "0.6.0" if variant == "v06" else "3.0.0"
    room = ROOM.replace('name="max_depth"', 'name="maxDepth"') if variant == "v06" else ROOM
    text = (f'<scene version="{version}">\n    {CAMERA.format(w=width, h=height)}\n    {room}\n'
            f'    {EMITTERS[variant]}\n</scene>\n')
    atomic.write(path, lambda tmp: open(tmp, "w").write(text))
    return path


def scene(variant, **kw):
    """write() into bench/results/scenes/sunsky-<variant>; the path of its scene.xml."""
    return write(os.path.join(FOLDER, f"sunsky-{variant}"), variant, **kw)
