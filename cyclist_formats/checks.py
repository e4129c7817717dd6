"""Up-front checks of command-line values and paths, shared by every command of both worlds.

Each check raises UserError with one line naming the flag, before any work starts, for the bad
input families that otherwise end in a traceback or a silent surprise: numbers of the right type
but an impossible value (a negative distance, an image size far beyond memory, a zero count, an
id out of range), output paths that exist as the wrong kind of thing or cannot be written, and
views folders whose cameras.json and images disagree.  numpy-free, so the add-on's Python imports
it too.
"""
import math
import os
import re

from .errors import UserError

# 8192² RGBA float32 is 1 GiB per image buffer; the rasterizer keeps several, so anything larger
# would exhaust memory long after the command started.
MAX_IMAGE_SIZE = 8192
# Beyond this many Gaussians a part/avatar no longer fits a CPU training step (~60 floats each,
# times Adam state and gradients).
MAX_GAUSSIANS = 20_000_000
MAX_THREADS = 1024
MAX_COUNT = 100_000_000


def _flag(name):
    """'image_size' -> '--image-size'; a name given as '--x' or with a space ("config field 'x'") is kept."""
    return name if name.startswith("-") or " " in name else "--" + name.replace("_", "-")


def finite(name, v):
    if v is None:
        return v
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise UserError(f"{_flag(name)} must be a finite number, got {v!r}")
    return v


def number(name, v, lo=None, hi=None, lo_open=False, hi_open=False):
    """A finite number within [lo, hi] (open ends with lo_open / hi_open); None passes."""
    if v is None:
        return v
    finite(name, v)
    bad_lo = lo is not None and (v <= lo if lo_open else v < lo)
    bad_hi = hi is not None and (v >= hi if hi_open else v > hi)
    if bad_lo or bad_hi:
        lo_s = "" if lo is None else ("(" if lo_open else "[") + f"{lo:g}"
        hi_s = "" if hi is None else f"{hi:g}" + (")" if hi_open else "]")
        if lo is not None and hi is not None:
            want = f"within {lo_s}, {hi_s}"
        elif lo is not None:
            want = f"{'>' if lo_open else '>='} {lo:g}"
        else:
            want = f"{'<' if hi_open else '<='} {hi:g}"
        raise UserError(f"{_flag(name)} must be {want}, got {v:g}")
    return v


def positive(name, v, hi=None):
    """A finite number > 0 (a distance, a time budget, a frame rate)."""
    return number(name, v, 0, hi, lo_open=True)


def integer(name, v, lo=None, hi=None):
    """An int within [lo, hi]; None passes."""
    if v is None:
        return v
    if isinstance(v, bool) or not isinstance(v, int):
        raise UserError(f"{_flag(name)} must be an integer, got {v!r}")
    return number(name, v, lo, hi)


def count(name, v, lo=1, hi=MAX_COUNT):
    """A count of things to make: at least `lo` (1: zero or negative counts make nothing)."""
    return integer(name, v, lo, hi)


def image_size(name, v, lo=16, hi=MAX_IMAGE_SIZE):
    return integer(name, v, lo, hi)


def threads(name, v):
    return integer(name, v, 1, MAX_THREADS)


def gaussians(name, v, lo=1):
    return integer(name, v, lo, MAX_GAUSSIANS)


def index(name, v, n):
    """An id/index in 0..n-1 (a ring view, a frame)."""
    return integer(name, v, 0, n - 1)


def _writable_dir(d, flag, target):
    """The nearest existing ancestor of d must be a writable folder."""
    d = os.path.abspath(d or ".")
    probe = d
    while not os.path.exists(probe):
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    if not os.path.isdir(probe):
        raise UserError(f"{flag} {target}: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {target}: cannot write in {probe} (permission denied)")


def output_file(name, path, suffixes=None):
    """An output file path: not an existing folder, its folder creatable and writable, and (if
    given) one of the allowed suffixes.  Nothing is created."""
    if path is None:
        return path
    flag = _flag(name)
    if not path or path.endswith(os.sep):
        raise UserError(f"{flag} must name a file, got {path!r}")
    if os.path.isdir(path):
        raise UserError(f"{flag} {path} is a folder; give a file name")
    if suffixes and not path.lower().endswith(tuple(s.lower() for s in suffixes)):
        raise UserError(f"{flag} must end in {' or '.join(suffixes)}, got {path}")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise UserError(f"{flag} {path}: cannot overwrite (permission denied)")
    _writable_dir(os.path.dirname(path), flag, path)
    return path


def output_dir(name, path):
    """An output folder path: not an existing file, creatable and writable.  Nothing is created."""
    if path is None:
        return path
    flag = _flag(name)
    if not path:
        raise UserError(f"{flag} must name a folder, got an empty path")
    if os.path.exists(path) and not os.path.isdir(path):
        raise UserError(f"{flag} {path} is a file, not a folder")
    if os.path.isdir(path) and not os.access(path, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {path}: cannot write in it (permission denied)")
    _writable_dir(os.path.dirname(os.path.abspath(path)), flag, path)
    return path


# a name that becomes a file or folder name (a dataset config's name): it cannot leave its folder
SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


def inside(root, path, what):
    """path, resolved (links and '..' followed), must lie inside root, resolved; returns path."""
    r, p = os.path.realpath(root), os.path.realpath(path)
    if os.path.commonpath([r, p]) != r:
        raise UserError(f"{what} {path} resolves to {p}, outside {r}")
    return path


def _existing(name, path, want_dir):
    if path is None:
        return path
    kind, other = ("folder", "file") if want_dir else ("file", "folder")
    if (os.path.isfile if want_dir else os.path.isdir)(path):
        raise UserError(f"{_flag(name)} {path} is a {other}, expected a {kind}")
    if not (os.path.isdir if want_dir else os.path.isfile)(path):
        raise UserError(f"{_flag(name)}: {kind} not found: {path}")
    return path


def input_file(name, path):
    return _existing(name, path, want_dir=False)


def input_dir(name, path):
    return _existing(name, path, want_dir=True)


def non_empty_file(name, path):
    """A config file that exists and holds more than whitespace and comments: an empty one
    would otherwise run on defaults without a word."""
    input_file(name, path)
    try:
        with open(path, "rb") as f:
            text = f.read(1 << 20)
    except OSError as e:
        raise UserError(f"{_flag(name)} {path}: cannot read ({e.strerror or e})") from None
    lines = [ln.strip() for ln in text.splitlines()]
    if not any(ln and not ln.startswith(b"#") for ln in lines):
        raise UserError(f"{_flag(name)} {path} is empty (no fields); write at least one field, "
                        f"or use a preset")
    return path


def views_folder(folder, flag="--views"):
    """A part's views folder whose cameras.json and rendered images agree, view for view.

    A camera without its image, or an image folder (rgba/NAME or img/NAME) without a camera,
    is refused: training on the rest would silently drop or mis-pose views."""
    import json

    input_dir(flag, folder)
    cam_path = os.path.join(folder, "cameras.json")
    if not os.path.isfile(cam_path):
        return folder  # transforms.json folders and missing cameras are the loader's one-liners
    try:
        with open(cam_path) as f:
            cams = json.load(f)
    except (OSError, ValueError, UnicodeDecodeError):
        return folder  # the loader names the exact problem
    if not isinstance(cams, dict):
        return folder
    names = sorted(k for k, v in cams.items() if isinstance(v, dict))
    have = set()
    for sub in ("rgba", "img"):
        d = os.path.join(folder, sub)
        if os.path.isdir(d):
            have |= {n for n in os.listdir(d) if os.path.isdir(os.path.join(d, n))}
    extra = sorted(have - set(names))
    if extra:
        raise UserError(f"{folder}: images for {len(extra)} view(s) not in cameras.json "
                        f"({', '.join(extra[:3])}{', ...' if len(extra) > 3 else ''}); re-render the views")
    missing = [n for n in names if not any(
        os.path.isfile(os.path.join(folder, sub, n, "0000" + ext))
        for sub, ext in (("rgba", ".png"), ("img", ".jpg"), ("img", ".png")))]
    if missing:
        raise UserError(f"{folder}: cameras.json lists {len(missing)} view(s) without images "
                        f"({', '.join(missing[:3])}{', ...' if len(missing) > 3 else ''}); re-render the views")
    return folder
