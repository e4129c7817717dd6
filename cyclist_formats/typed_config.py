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
import dataclasses
import math
import types
import typing
from typing import Annotated, Any, Optional

from pydantic import BaseModel, ConfigDict, Field, PlainValidator, Strict, ValidationError
from pydantic_core import PydanticCustomError

from .errors import UserError

__all__ = ["Block", "Number", "Int", "Bool", "Str", "Range", "IntRange", "Vec3", "AutoOr", "Field",
           "validate", "field_error", "defaults_of", "add_model_arguments", "overrides_of", "add_dataclass_arguments",
           "dataclass_from_args"]


class Block(BaseModel):
    """One config block: unknown fields are errors (a typo would otherwise fall back to a default).
    Frozen: a config is passed to the stages as this object, and none of them may change it on the
    way (a dataset sample is a function of config and index); a changed copy is
    `cfg.model_copy(update={...})`."""
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


# ------------------------------------------------------------------ errors

def field_error(field, msg, what="config field"):
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


def validate(model, raw, what="config field"):
    """raw mapping -> model instance; the first error as one UserError naming its field."""
    try:
        return model.model_validate(raw)
    except ValidationError as e:
        field, msg = _describe(e.errors(include_url=False)[0], model)
        raise field_error(field, msg, what) from None


# ------------------------------------------------------------------ command line

def _flag_kind(annotation):
    """argparse keywords for a field's type: lists take several values, ints are parsed as ints."""
    t = annotation
    while typing.get_origin(t) is Annotated:
        t = typing.get_args(t)[0]
    members = [a for a in typing.get_args(t) if a is not type(None)] \
        if typing.get_origin(t) in (typing.Union, types.UnionType) else [t]
    for m in members:
        while typing.get_origin(m) is Annotated:
            m = typing.get_args(m)[0]
        if m is list or typing.get_origin(m) is list:
            return {"nargs": "+", "metavar": "ID"}
    t = members[0]
    while typing.get_origin(t) is Annotated:
        t = typing.get_args(t)[0]
    return {"type": t} if t in (int, float) else {}


def add_model_arguments(parser, model, fields, help_suffix="overrides the config's {name}"):
    """One --flag per named field of a pydantic model, typed from its annotation, help from its
    description; default None (the flag overrides the config only when given)."""
    for name in fields:
        f = model.model_fields[name]
        if not f.description:
            raise ValueError(f"{model.__name__}.{name} has no description for its --help")
        helptext = f"{f.description}; {help_suffix.format(name=name)}"
        parser.add_argument("--" + name.replace("_", "-"), dest=name, default=None,
                            help=helptext.replace("%", "%%"), **_flag_kind(f.annotation))


def overrides_of(args, fields):
    """{field: value} of the flags given on the command line (None: not given)."""
    return {name: getattr(args, name) for name in fields}


# Dataclass configs (the training stages'): every field whose metadata has a "help" becomes
# --field-name with the field's default, type and metadata "choices"; a field holding a dataclass
# contributes its own fields (dest "outer_inner", flag named after the inner field).

def _dataclass_flags(obj, path=()):
    """(attribute path, field, default) of every exposed option of the dataclass instance obj."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if "help" in f.metadata:
            yield path + (f.name,), f, value
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            yield from _dataclass_flags(value, path + (f.name,))


def add_dataclass_arguments(parser, defaults):
    """The options of a dataclass config; defaults: an instance (its values are the defaults)."""
    for path, f, d in _dataclass_flags(defaults):
        kw = {"help": f.metadata["help"] + " (default %(default)s)"}
        if isinstance(d, bool):  # --x / --no-x (type=bool would read "False" as true)
            kw.update(default=d, action=argparse.BooleanOptionalAction)
        elif isinstance(d, tuple):
            kw.update(default=",".join(map(str, d)), type=str)
        else:
            kw.update(default=d, type=type(d))
        if "choices" in f.metadata:
            kw["choices"] = f.metadata["choices"]
        parser.add_argument("--" + f.name.replace("_", "-"), dest="_".join(path), **kw)


def _int_tuple(flag, text):
    try:
        return tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise UserError(f"--{flag} wants comma-separated integers, got {text!r}") from None


def dataclass_from_args(args, defaults, **extra):
    """A copy of the dataclass instance defaults with the parsed options set (extra: further fields)."""
    cfg = dataclasses.replace(defaults, **extra)
    for path, f, d in _dataclass_flags(defaults):
        v = getattr(args, "_".join(path))
        if isinstance(d, tuple):
            v = _int_tuple(f.name.replace("_", "-"), v)
        obj = cfg
        for p in path[:-1]:
            inner = dataclasses.replace(getattr(obj, p))  # no sharing with defaults' nested instance
            setattr(obj, p, inner)
            obj = inner
        setattr(obj, path[-1], v)
    return cfg
