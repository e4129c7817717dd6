"""Reading the text files a user hands a command (YAML configs, the rider roster, JSON records):
every failure, a missing file, bytes that are not UTF-8, bad YAML or JSON, is one UserError line
naming the file, never a traceback (docs/contract.md: text files are UTF-8)."""
import json

from .errors import UserError


def _read(path, what, missing):
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise UserError(missing or f"{path}: missing ({what})") from None
    except OSError as e:
        raise UserError(f"cannot read {path}: {e.strerror or e} (expected a {what})") from None


def _decode(path, data, invalid):
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise UserError(invalid.format(path=path, error=f"not UTF-8 text (byte 0x{data[e.start]:02x} at offset "
                                                        f"{e.start}); save it as UTF-8")) from None


def read_text(path, what="text file", missing=None):
    """The file's text, decoded as UTF-8 (`missing`: the message for a file that does not exist)."""
    return _decode(path, _read(path, what, missing), "{path}: {error}")


def read_yaml(path, what="YAML file", missing=None, invalid="{path} is not valid YAML: {error}"):
    """The file's YAML document (None for an empty file or one of comments only); `invalid`: the
    message for a file that is not UTF-8 YAML, with {path} and {error} (the parser's first line)."""
    # PyYAML only here: this package is copied into the Blender add-on (relative imports), and
    # Blender's own Python has no yaml; the add-on reads JSON only
    import yaml

    text = _decode(path, _read(path, what, missing), invalid)
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise UserError(invalid.format(path=path, error=str(e).splitlines()[0])) from None


def read_json(path, what="JSON file", missing=None):
    """The file's JSON document."""
    text = _decode(path, _read(path, what, missing), "{path} is not valid JSON: {error}")
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise UserError(f"{path} is not valid JSON: {e}") from None
