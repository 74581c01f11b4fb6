"""User-facing errors: one line that names the file, the thing and what would be accepted.

The CLI prints `tracer: <message>` and exits with code 2 for every `TracerError`;
anything else is a bug and keeps its traceback.
"""


class TracerError(Exception):
    """An error caused by the user's input (file, option, setting), not by the tracer."""


class SceneError(TracerError):
    """A scene file (OBJ, MTL, JSON sidecar, texture) is missing or malformed."""


class SettingsError(TracerError):
    """An unknown or invalid option or setting."""


def unknown_name(kind: str, name: str, valid) -> SettingsError:
    """Error for an unknown registered name, listing the valid ones."""
    valid = sorted(valid)
    return SettingsError(f"unknown {kind} {name!r}; valid: {', '.join(valid)}")
