"""Writes that a killed run cannot leave half done: each output goes to a temporary file in its
own folder (tracer.imageio.temp_path: same extension, so that image writers pick the same format)
and is renamed into place with os.replace, so the file holds either the last complete output or
the new one; write_all replaces a group of files (an image and its metadata) together."""
import json
import os

from tracer.imageio import temp_path


def _commit(tmp, path):
    try:
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write(path, writer):
    """writer(tmp_path) writes the whole output to tmp_path; it then replaces `path`."""
    write_all([(path, writer)])


def write_all(outputs):
    """[(path, writer)]: every writer(tmp_path) runs first, then every file is renamed into place,
    so that files that belong together (an image and its metadata) are replaced together or not at
    all (but for the instant between the renames)."""
    done = []
    try:
        for path, writer in outputs:
            tmp = temp_path(path)
            done.append((tmp, os.fspath(path)))
            writer(tmp)
    except BaseException:
        for tmp, _ in done:
            if os.path.exists(tmp):
                os.remove(tmp)
        raise
    for tmp, path in done:
        _commit(tmp, path)


def text_writer(text):
    """A writer for write/write_all that writes `text`."""
    def w(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())

    return w


def image_writer(array, **kw):
    """A writer for write/write_all that writes an image (tracer.write_image)."""
    import tracer

    return lambda tmp: tracer.write_image(tmp, array, **kw)


def write_text(path, text):
    write(path, text_writer(text))


def write_json(path, obj, **kw):
    write_text(path, json.dumps(obj, **kw))


def write_jsonl(path, records):
    write_text(path, "".join(json.dumps(r) + "\n" for r in records))


def save_npy(path, array):
    import numpy as np

    def w(tmp):
        with open(tmp, "wb") as f:
            np.save(f, array)
            f.flush()
            os.fsync(f.fileno())

    write(path, w)


def save_npz(path, **arrays):
    import numpy as np

    def w(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())

    write(path, w)


def write_image(path, array, **kw):
    write(path, image_writer(array, **kw))
