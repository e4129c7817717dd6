"""Write-then-rename helpers: a killed run never leaves a truncated file under the final name."""
import json
import os
import tempfile
from contextlib import contextmanager


def temp_name(path):
    """A fresh hidden temporary name beside `path` that keeps its extension.

    Blender and PIL pick formats by extension; the leading dot and '.tmp' mark it as stale if a
    run is killed (remove_stale deletes those).
    """
    path = os.fspath(path)
    d = os.path.dirname(path) or "."
    os.makedirs(d, exist_ok=True)
    base, ext = os.path.splitext(os.path.basename(path))
    fd, tmp = tempfile.mkstemp(prefix="." + base + ".", suffix=".tmp" + ext, dir=d)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; finished files get the usual mode
    return tmp


def is_temp_name(name):
    """True for the hidden temporaries temp_name makes (left behind only by a killed run)."""
    base = os.path.basename(name)
    return base.startswith(".") and ".tmp" in base


def remove_stale(folder):
    """Delete the temporaries a killed run left anywhere below `folder`; returns how many."""
    n = 0
    for root, _, files in os.walk(folder):
        for name in files:
            if is_temp_name(name):
                os.remove(os.path.join(root, name))
                n += 1
    return n


@contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path`; rename it onto `path` only if the block succeeds."""
    path = os.fspath(path)
    tmp = temp_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_json(path, obj, indent=1):
    # json.dumps, not json.dump: dump always streams through the pure-Python encoder, dumps uses
    # the C one when indent is None (a dataset shard: 6 ms -> <1 ms); the text is the same
    text = json.dumps(obj, indent=indent)
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            f.write(text + "\n")


def read_json_or_none(path):
    """A JSON record that decides whether work is done (resume markers, metrics, reports): None when
    it is missing or unreadable, so the work is simply redone."""
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def write_bytes(path, data):
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
