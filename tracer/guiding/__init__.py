"""Directional samplers for the bounce direction, registered by name.

`bsdf` is plain BSDF importance sampling (no guide). Guides that learn (grid, photon,
odis, pss) register here as they land; each is built from a settings dict, and unknown
names or settings are errors that list the valid ones.
"""
from ..errors import SettingsError, unknown_name

# name -> (factory or None for plain BSDF sampling, {setting: default})
REGISTRY = {
    "bsdf": (None, {}),
}


def guide_names():
    return tuple(REGISTRY)


def make_guide(name, **settings):
    """Build the guide registered as `name`; None means plain BSDF sampling."""
    if name not in REGISTRY:
        raise unknown_name("guide", name, REGISTRY)
    factory, defaults = REGISTRY[name]
    bad = sorted(set(settings) - set(defaults))
    if bad:
        valid = ", ".join(sorted(defaults)) or "none"
        raise SettingsError(f"guide {name!r} has no setting {bad[0]!r}; valid: {valid}")
    if factory is None:
        return None
    return factory(**dict(defaults, **settings))
