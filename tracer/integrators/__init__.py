"""Integrators, registered by name like the guides: `path` (unidirectional path tracing) and
`gpt` (gradient-domain path tracing). Each is an integrators.base.Integrator with its settings;
`make_integrator("gpt:shift=replay,recon=l1")` (the spec grammar of tracer.methods) or
`make_integrator("gpt", shift="replay")` builds one, an unknown name or setting being one error
that lists the valid ones."""
from ..errors import SettingsError, unknown_name
from ..methods import parse_spec
from .base import Integrator
from .gpt import GptIntegrator
from .path import PathIntegrator

REGISTRY = {"path": PathIntegrator, "gpt": GptIntegrator}


def integrator_names():
    return tuple(REGISTRY)


def integrator_settings(name):
    """{setting: default} of integrator `name`."""
    if name not in REGISTRY:
        raise unknown_name("integrator", name, REGISTRY)
    return dict(REGISTRY[name].DEFAULTS)


def make_integrator(spec="path", **settings):
    """The integrator of `spec` (a name or NAME:KEY=VALUE,...), with `settings` over the spec's; an
    Integrator object is returned as it is (settings then must be empty)."""
    if isinstance(spec, Integrator):
        if settings:
            raise SettingsError("integrator settings go with an integrator name, not with an integrator object")
        return spec
    name, given = parse_spec(spec)
    if name not in REGISTRY:
        raise unknown_name("integrator", name, REGISTRY)
    return REGISTRY[name](**dict(given, **settings))
