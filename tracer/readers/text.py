"""What the scene readers share: reading a file as text or JSON, checking keys and values, and
warnings that name the file (each recorded in the scene's warnings and logged)."""
import json
import logging
import math

import numpy as np

from ..errors import SceneError

log = logging.getLogger("tracer")


def warn(scene_warnings, msg, level=logging.WARNING):
    """Record `msg` in the scene's warnings and log it (at `level`: INFO for what changes no pixel,
    which the command line shows only with -v)."""
    scene_warnings.append(msg)
    log.log(level, msg)


def read_json(path):
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise SceneError(f"{path}: scene file not found") from None
    except json.JSONDecodeError as e:
        raise SceneError(f"{path}: malformed JSON at line {e.lineno}: {e.msg}") from None
    if not isinstance(data, dict):
        raise SceneError(f"{path}: a scene sidecar must be a JSON object")
    return data


def check_keys(where, got, allowed):
    bad = sorted(set(got) - set(allowed))
    if bad:
        raise SceneError(f"{where}: unknown key {bad[0]!r}; valid: {', '.join(sorted(allowed))}")


def vec3(where, value):
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SceneError(f"{where}: expected three finite numbers, got {value!r}")
    return v


def number(where, value, kind=float, lo=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}: expected a number, got {value!r}")
    if kind is int and value != int(value):
        raise SceneError(f"{where}: expected an integer, got {value!r}")
    value = kind(value)
    if not math.isfinite(value) or (lo is not None and value < lo):
        raise SceneError(f"{where}: expected a finite number >= {lo}, got {value!r}")
    return value


def read_bytes(path, what):
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise SceneError(f"{path}: {what} file not found") from None
    except OSError as e:
        raise SceneError(f"{path}: cannot read {what} ({e.strerror})") from None


def check_text(path, data, what):
    """`data` (a file's bytes), or SceneError unless it looks like text: a NUL byte in its first
    64 KiB (and no UTF-16 byte-order mark) means a binary file, e.g. a binary PLY or FBX named .obj."""
    head = data[:65536]
    nul = head.find(b"\x00")
    if nul >= 0 and not head.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise SceneError(f"{path}: not a text {what} file (it holds binary data: a zero byte at offset {nul})")
    return data


def read_text(path, what):
    """The text of an OBJ or MTL file: UTF-8 (with or without a BOM), else the encoding
    charset_normalizer finds most likely (a Latin-1 comment is common in exported files)."""
    data = read_bytes(path, what)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        pass
    import charset_normalizer

    best = charset_normalizer.from_bytes(data).best()
    return str(best) if best is not None else data.decode("latin-1")
