"""Typed configs: pydantic v2 models, checked field by field, errors as one line naming the field,
and command-line flags derived from the same models.

Why pydantic (rather than dataclasses checked by hand): ranges sit in the field declarations
(Field(ge=..., le=...)), extra="forbid" turns a typo into an error instead of a silent default, every
error carries the path of its field (one line: `config field 'street.distance_m': ...`), and the JSON
schema comes for free (Model.model_json_schema()).

Values keep the type they were written with (an int stays an int, a [min, max] list stays the list
given): the validated config is dumped back to a dict, and that dict is stored beside a dataset, so
its bytes must not depend on how the check was made.
"""
import argparse
import math
import types
import typing
from typing import Annotated, Any, Optional

from pydantic import BaseModel, ConfigDict, Field, PlainValidator, Strict, ValidationError
from pydantic_core import PydanticCustomError

from .errors import UserError

__all__ = ["Block", "Number", "Int", "Bool", "Str", "Range", "IntRange", "Vec3", "AutoOr", "Field", "record_of", "updated",
           "Choice", "validate", "field_error", "defaults_of", "add_model_arguments", "overrides_of",
           "model_from_args", "options_of", "flag_of", "dest_of"]


class Block(BaseModel):
    """One config block: unknown fields are errors (a typo would otherwise fall back to a default).
    Frozen: a config is passed to the stages as this object, and none of them may change it on the
    way (a dataset sample is a function of config and index); a changed copy is
    `cfg.model_copy(update={...})`, or `updated(cfg, ...)` to have the copy checked too."""
    # defer_build: the validators are built on first use, not at import (the --help builders read
    # only the field declarations; measured 0.24 s of a loaded 2-core machine's import)
    model_config = ConfigDict(extra="forbid", defer_build=True, frozen=True)


def defaults_of(model):
    """{field: default} of a block of plain fields, without building its validator (import time)."""
    return {k: f.get_default(call_default_factory=True) for k, f in model.model_fields.items()}


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _number(v):
    if not _is_number(v):
        raise PydanticCustomError("number", "expected a finite number")
    return v  # as written: 0 stays 0, not 0.0 (the stored config's bytes)


# a finite int or float (not a bool, not NaN or inf), kept as given; ranges via Field(ge=..., le=...)
Number = Annotated[float, PlainValidator(_number, json_schema_input_type=float)]
Int = Annotated[int, Strict()]      # no bool, no 3.0, no "3"
Bool = Annotated[bool, Strict()]    # no "yes", no 1
Str = Annotated[str, Strict()]


def _bounds_text(lo, hi):
    return f"[{lo}, {hi}]"


def Range(lo=None, hi=None):
    """A [min, max] pair of numbers with min <= max, both within [lo, hi] (None: open)."""
    def check(v):
        if not (isinstance(v, list) and len(v) == 2 and all(_is_number(x) for x in v) and v[0] <= v[1]):
            raise PydanticCustomError("range", "expected [min, max] with min <= max")
        if (lo is not None and v[0] < lo) or (hi is not None and v[1] > hi):
            raise PydanticCustomError("range_bounds", "expected values within {bounds}",
                                      {"bounds": _bounds_text(lo, hi)})
        return list(v)
    return Annotated[list, PlainValidator(check, json_schema_input_type=list[float])]


def IntRange(lo, hi):
    """A [min, max] pair of integers with lo <= min <= max <= hi."""
    def check(v):
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) and not isinstance(x, bool) for x in v)
                and lo <= v[0] <= v[1] <= hi):
            raise PydanticCustomError("int_range", "expected [min, max] integers within {lo}..{hi}", {"lo": lo, "hi": hi})
        return list(v)
    return Annotated[list, PlainValidator(check, json_schema_input_type=list[int])]


def Choice(*values):
    """One of the values, of its exact type (no True for 1, no 1.0 for 1: Literal alone takes them)."""
    def check(v):
        if not any(type(v) is type(c) and v == c for c in values):
            raise PydanticCustomError("choice", "expected one of {values}", {"values": ", ".join(map(repr, values))})
        return v
    return Annotated[typing.Literal[values], PlainValidator(check, json_schema_input_type=typing.Literal[values])]


def _vec3(v):
    if not (isinstance(v, list) and len(v) == 3 and all(_is_number(x) for x in v)):
        raise PydanticCustomError("vec3", "expected [x, y, z]")
    return list(v)


Vec3 = Annotated[list, PlainValidator(_vec3, json_schema_input_type=list[float])]


def AutoOr(lo, hi):
    """'auto' or a number within [lo, hi]."""
    def check(v):
        if v != "auto" and not (_is_number(v) and lo <= v <= hi):
            raise PydanticCustomError("auto_or", "expected auto or a number within {bounds}",
                                      {"bounds": _bounds_text(lo, hi)})
        return v
    return Annotated[Any, PlainValidator(check, json_schema_input_type=Optional[float])]


def updated(cfg, **fields):
    """A checked copy of cfg with fields changed; a nested block's fields as a dict
    (updated(cfg, iterations=500, densify={"max_gaussians": 4000})).  Unlike model_copy(update=...),
    the copy is validated: a bad value is one UserError naming its field."""
    raw = cfg.model_dump()
    for k, v in fields.items():
        raw[k] = {**raw[k], **v} if isinstance(v, dict) and isinstance(getattr(cfg, k, None), BaseModel) else v
    return validate(type(cfg), raw)


def _lists(v):
    return [_lists(x) for x in v] if isinstance(v, (tuple, list)) else v


def record_of(cfg):
    """A config as the records on disk hold it (PART.json's and posed_train.json's "config", the
    library's posed_<field> settings): the one place a training config becomes a dict.  Every field in
    declaration order, nested blocks as objects, tuples as lists (as JSON reads them back, so a record
    compares equal to one read from disk), values as given (an int stays an int), less the fields the
    model lists in RECORD_EXCLUDE (those that change nothing trained, e.g. the progress line)."""
    d = cfg.model_dump(exclude=set(getattr(cfg, "RECORD_EXCLUDE", ())))
    return {k: _lists(v) if isinstance(v, tuple) else v for k, v in d.items()}


# ------------------------------------------------------------------ errors

def field_error(field, msg, what="config field"):
    """One line naming the field (`config field 'street.distance_m': expected ...`); what=None: the
    field is a command-line flag, worded as cyclist_formats.checks words every other flag
    (`--eps2d must be > 0, got 0.0`)."""
    if what is None:
        msg = msg.replace(": expected", " expected").replace("expected a value ", "must be ")
        return UserError(f"{field} {msg.replace('expected ', 'must be ')}")
    return UserError(f"{what} '{field}': {msg}")


def _strip(t):
    """The model class inside Optional[...] / Annotated[...] / list[...], or None."""
    while True:
        origin = typing.get_origin(t)
        if origin is Annotated:
            t = typing.get_args(t)[0]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(t) if a is not type(None)]
            t = args[0] if len(args) == 1 else None
        elif origin is list:
            t = typing.get_args(t)[0] if typing.get_args(t) else None
        else:
            return t if isinstance(t, type) and issubclass(t, BaseModel) else None


def _model_at(model, loc):
    for part in loc:
        if isinstance(part, int) or model is None:
            continue
        f = model.model_fields.get(part)
        model = _strip(f.annotation) if f is not None else None
    return model


_COMPARE = {"greater_than_equal": (">=", "ge"), "greater_than": (">", "gt"), "less_than_equal": ("<=", "le"),
            "less_than": ("<", "lt")}
_KINDS = {"int_type": "an integer", "int_from_float": "an integer", "int_parsing": "an integer",
          "bool_type": "true or false", "bool_parsing": "true or false", "string_type": "a string",
          "list_type": "a list", "float_type": "a number"}


def _message(err):
    """pydantic's message in the config's words ("expected a value >= 1")."""
    kind, ctx = err["type"], err.get("ctx") or {}
    if kind in _COMPARE:
        op, key = _COMPARE[kind]
        return f"expected a value {op} {ctx[key]}"
    if kind in _KINDS:
        return f"expected {_KINDS[kind]}"
    if kind == "literal_error":
        return f"expected {ctx['expected']}"
    if kind == "too_short":
        return f"expected at least {ctx['min_length']} item(s)"
    msg = err["msg"].replace("Input should be", "expected")
    return msg[0].lower() + msg[1:]


def _describe(err, model):
    """(field path, message) of one pydantic error: list positions of scalars go into the message,
    positions of blocks into the path (lod.levels[1].keep)."""
    loc = list(err["loc"])
    path, item = "", None
    for i, part in enumerate(loc):
        if isinstance(part, int):
            if i == len(loc) - 1:
                item = part
            else:
                path += f"[{part}]"
        else:
            path += ("." if path else "") + str(part)
    kind, value = err["type"], err.get("input")
    if kind == "extra_forbidden":
        owner = _model_at(model, loc[:-1])
        known = ", ".join(owner.model_fields) if owner is not None else ""
        return path, f"unknown field (known: {known or 'none'})"
    if kind in ("model_type", "dict_type"):
        return path or "<top>", f"expected a mapping, got {type(value).__name__}"
    if kind == "missing":
        return path, "missing (a required field)"
    msg = _message(err)
    if item is not None:
        msg = f"item {item}: {msg}"
    return path or "<top>", f"{msg}, got {value!r}"


def validate(model, raw, what="config field", name=None):
    """raw mapping -> model instance; the first error as one UserError naming its field (name: field
    path -> the name to show, e.g. its command-line flag)."""
    try:
        return model.model_validate(raw)
    except ValidationError as e:
        field, msg = _describe(e.errors(include_url=False)[0], model)
        raise field_error(name(field) if name else field, msg, what) from None


# ------------------------------------------------------------------ command line
# One builder for every command whose options are config fields: the dataset command's overrides of
# its config file and the training commands' options (train, bike-posed-train, rider-posed-train,
# relight-fit, rider-avatar) alike.  A flag's default is None (not given): the config's value stands, so the default lives in
# the field declaration only, and --help shows it from there.

def _field_at(model, path):
    """(model holding the field, FieldInfo) of a dotted path ("densify.max_gaussians")."""
    *outer, name = path.split(".")
    for part in outer:
        model = _strip(model.model_fields[part].annotation)
    return model, model.model_fields[name]


def options_of(model, prefix=""):
    """The field paths of a model's command-line options: every field with a description, and those
    of a nested block (a field holding a Block, whose own description is not needed), in declaration
    order ("iterations", ..., "densify.max_gaussians")."""
    out = []
    for name, f in model.model_fields.items():
        inner = _strip(f.annotation)
        if inner is not None and not f.description:
            out += options_of(inner, prefix + name + ".")
        elif f.description:
            out.append(prefix + name)
    return tuple(out)


def flag_of(path):
    """The command-line flag of a field path: its last name ("densify.max_gaussians" -> --max-gaussians)."""
    return "--" + path.rsplit(".", 1)[-1].replace("_", "-")


def dest_of(path):
    """The argparse dest of a field path ("densify.max_gaussians" -> densify_max_gaussians)."""
    return path.replace(".", "_")


def _members(annotation):
    """The non-None types of an annotation, Annotated[...] stripped."""
    t = annotation
    while typing.get_origin(t) is Annotated:
        t = typing.get_args(t)[0]
    members = [a for a in typing.get_args(t) if a is not type(None)] \
        if typing.get_origin(t) in (typing.Union, types.UnionType) else [t]
    out = []
    for m in members:
        while typing.get_origin(m) is Annotated:
            m = typing.get_args(m)[0]
        out.append(m)
    return out


def _is_tuple(annotation):
    return any(m is tuple or typing.get_origin(m) is tuple for m in _members(annotation))


def _flag_kind(annotation):
    """argparse keywords for a field's type: lists take several values, a tuple of integers is one
    comma list, a Choice lists its values, bools are --x / --no-x, ints are parsed as ints."""
    members = _members(annotation)
    for m in members:
        if m is list or typing.get_origin(m) is list:
            return {"nargs": "+", "metavar": "ID"}
    if _is_tuple(annotation):  # parsed by model_from_args, so that a bad list is the field's one line
        return {}
    t = members[0]
    if typing.get_origin(t) is typing.Literal:
        values = typing.get_args(t)
        return {"choices": values, "type": type(values[0])}
    if t is bool:  # type=bool would read "False" as true
        return {"action": argparse.BooleanOptionalAction}
    return {"type": t} if t in (int, float) else {}


def _shown(v):
    return ",".join(map(str, v)) if isinstance(v, tuple) else str(v)


def add_model_arguments(parser, model, fields, help_suffix="; overrides the config's {name}"):
    """One --flag per named field of a pydantic model (a dotted path reaches a nested block's field;
    the flag is named after the field itself), typed from its annotation, help from its description
    plus help_suffix ({name}: the field path, {default}: its default; or a callable (path, default)
    -> text); default None (the flag overrides the config only when given)."""
    for path in fields:
        owner, f = _field_at(model, path)
        if not f.description:
            raise ValueError(f"{owner.__name__}.{path.rsplit('.', 1)[-1]} has no description for its --help")
        default = _shown(f.get_default(call_default_factory=True))
        suffix = help_suffix(path, default) if callable(help_suffix) else help_suffix.format(name=path, default=default)
        helptext = f.description + suffix
        parser.add_argument(flag_of(path), dest=dest_of(path), default=None,
                            help=helptext.replace("%", "%%"), **_flag_kind(f.annotation))


def overrides_of(args, fields):
    """{field: value} of the flags given on the command line (None: not given)."""
    return {name: getattr(args, dest_of(name)) for name in fields}


def _int_tuple(flag, text):
    try:
        return tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UserError(f"{flag} wants comma-separated integers, got {text!r}") from None


def model_from_args(model, args, fields, base=None, **extra):
    """The model of a command line's flags (add_model_arguments) over the fields' defaults (or over
    base, a model instance: a command whose defaults depend on another option), plus extra fields;
    the first bad value is one UserError naming its flag ("--eps2d must be <= 10, got 11.0")."""
    raw = base.model_dump() if base is not None else {}
    for path in fields:
        v = getattr(args, dest_of(path))
        if v is None:
            continue
        if _is_tuple(_field_at(model, path)[1].annotation):
            v = _int_tuple(flag_of(path), v)
        *outer, name = path.split(".")
        d = raw
        for part in outer:
            d = d.setdefault(part, {})
        d[name] = v
    raw.update(extra)
    flags = {p: flag_of(p) for p in fields}
    return validate(model, raw, None, lambda path: flags.get(path, path))
