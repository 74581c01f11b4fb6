"""Method specs: one grammar for guides and integrators, in the CLI, the library and `bench`.

A spec is a registered name, optionally followed by settings:

    photon
    photon:iterations=6,sigma=2
    gpt:shift=replay,recon=l2
    path:nee=0

`parse_spec(text)` returns (name, {setting: value}); values read as int, then float, else text.
`format_spec(name, settings)` writes one back. `check_settings(kind, name, settings, defaults)`
merges settings over a method's defaults, with one clear error for a setting it does not have.
"""
import re

from .errors import SettingsError

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_+.-]*")


def parse_value(text):
    """`text` as an int, else a float, else the text itself."""
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            continue
    return text


def parse_settings(items, what="setting"):
    """KEY=VALUE strings as a dict (values by parse_value); SettingsError naming `what` for an
    item that is not KEY=VALUE."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise SettingsError(f"{what} {item!r}: expected KEY=VALUE")
        out[key] = parse_value(value.strip())
    return out


def parse_spec(text):
    """(name, settings) of a method spec `name[:key=value,...]`."""
    if not isinstance(text, str):
        raise SettingsError(f"a method spec is a string such as 'photon:iterations=6', got {text!r}")
    name, _, rest = text.partition(":")
    name = name.strip()
    if not _NAME.fullmatch(name):
        raise SettingsError(f"method spec {text!r}: expected NAME or NAME:KEY=VALUE,...")
    items = [s for s in rest.split(",") if s.strip()] if rest else []
    return name, parse_settings(items, f"method spec {text!r}:")


def format_spec(name, settings=None):
    """The spec text of `name` with `settings` (in the order given)."""
    if not settings:
        return name
    return name + ":" + ",".join(f"{k}={v}" for k, v in settings.items())


def check_settings(kind, name, settings, defaults):
    """`defaults` updated by `settings`; SettingsError for a key `defaults` lacks, naming the valid ones."""
    bad = sorted(set(settings) - set(defaults))
    if bad:
        valid = ", ".join(sorted(defaults)) or "none"
        raise SettingsError(f"{kind} {name!r} has no setting {bad[0]!r}; valid: {valid}")
    return dict(defaults, **settings)
