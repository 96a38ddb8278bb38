"""Parameters: frozen, documented dataclasses with strict loading from TOML-like dictionaries (the
bottom floor: it imports nothing of fbmflow, so that every package can declare its own sections).

Every scene's parameters are a tree of frozen dataclasses (:class:`Section` subclasses) whose
fields are declared with :func:`param` (default, unit, documentation and constraints). A section
checks its values when it is made, so ``FluidParams(viscosity=-1.0)`` fails at once;
:func:`from_dict` builds a tree from nested dictionaries and rejects unknown keys, wrong types and
values outside the constraints with a :class:`ParamError` that names the dotted key and what is
allowed; a key a section has renamed (its ``renamed`` mapping) names the new one. ``--set
a.b=value`` overrides use :func:`set_dotted` and :func:`parse_value`.

The sections live with what they configure: :class:`~fbmflow.params.FluidParams` and
:class:`~fbmflow.params.TimeParams` in :mod:`fbmflow.params`, the solver settings in
:mod:`fbmflow.solvers.settings`, the coupling and fictitious boundary in
:mod:`fbmflow.coupling.settings`, contact and repulsion in :mod:`fbmflow.contact.settings`.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import sys
import tomllib
import typing
from typing import Any


class ParamError(ValueError):
    """Invalid user input (scene file, parameter, command line); the message is one line."""


def param(default, doc: str, unit: str = "", *, positive: bool = False, nonnegative: bool = False,
          choices: tuple | None = None, minimum: float | None = None, maximum: float | None = None):
    """A documented dataclass field with validation metadata."""
    meta = dict(doc=doc, unit=unit, positive=positive, nonnegative=nonnegative, choices=choices,
                minimum=minimum, maximum=maximum)
    if dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=lambda: default, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def check_types(owner: str, **arguments) -> None:
    """TypeError naming the argument, unless every ``name=(value, cls)`` in ``arguments`` has
    ``isinstance(value, cls)``; ``name=(value, cls, None)`` also accepts None."""
    for name, (value, cls, *none) in arguments.items():
        if not (isinstance(value, cls) or (none and value is None)):
            expected = cls.__name__ + (" or None" if none else "")
            raise TypeError(f"{owner}: {name} must be a {expected}, got {type(value).__name__}; "
                            f"make it with {cls.__name__}(...) or fbmflow.config.from_dict")


def section(cls, doc: str = ""):
    """A nested parameter section with its default instance."""
    return dataclasses.field(default_factory=cls, metadata=dict(doc=doc or (cls.__doc__ or "").strip()))


def _check_value(key: str, value: Any, ftype, meta) -> Any:
    if ftype is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(f"{key}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ParamError(f"{key}: must be finite, got {value!r}")
    elif ftype is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParamError(f"{key}: expected an integer, got {value!r}")
    elif ftype is bool:
        if not isinstance(value, bool):
            raise ParamError(f"{key}: expected true or false, got {value!r}")
    elif ftype is str:
        if not isinstance(value, str):
            raise ParamError(f"{key}: expected a string, got {value!r}")
    if meta.get("choices") is not None and value not in meta["choices"]:
        allowed = ", ".join(repr(c) for c in meta["choices"])
        raise ParamError(f"{key}: {value!r} is not allowed; choose one of {allowed}")
    if meta.get("positive") and not value > 0:
        raise ParamError(f"{key}: must be positive, got {value!r}")
    if meta.get("nonnegative") and not value >= 0:
        raise ParamError(f"{key}: must be zero or positive, got {value!r}")
    if meta.get("minimum") is not None and value < meta["minimum"]:
        raise ParamError(f"{key}: must be at least {meta['minimum']}, got {value!r}")
    if meta.get("maximum") is not None and value > meta["maximum"]:
        raise ParamError(f"{key}: must be at most {meta['maximum']}, got {value!r}")
    return value


@functools.cache
def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


class Section:
    """Base of the parameter dataclasses: a section checks its values when it is made.

    Every field declared with :func:`param` is checked against its type (an integer is accepted
    for a float and stored as one) and its constraints, nested sections against their class,
    and then ``validate()``, when the section has one, checks what spans several keys; a
    violation raises :class:`ParamError` naming ``Class.field`` and what is allowed. A section's
    class attribute ``renamed`` (old key -> new dotted key, relative to the section) makes
    :func:`from_dict` answer an old key with the new one.
    """

    def __post_init__(self):
        hints = _hints(type(self))
        for f in dataclasses.fields(self):
            value, ftype = getattr(self, f.name), hints[f.name]
            if dataclasses.is_dataclass(ftype):
                if not isinstance(value, ftype):
                    raise ParamError(f"{type(self).__name__}.{f.name}: expected a {ftype.__name__}, "
                                     f"got {value!r}")
                continue
            object.__setattr__(self, f.name, _check_value(f"{type(self).__name__}.{f.name}", value, ftype,
                                                          f.metadata))
        validate = getattr(self, "validate", None)
        if validate is not None:
            validate()


def derive(base: type, name: str, doc: str, **changes) -> type:
    """A frozen subclass ``name`` of the section ``base`` with other defaults.

    Each change names a field of ``base``: a plain value replaces its default (its doc, unit and
    bounds stay), a :func:`param` replaces the whole field. The class belongs to the calling
    module. ValueError when ``base`` has no such field. For example
    ``derive(TimeParams, "SlowTime", "Time stepping.", dt=0.1)``."""
    fields, hints = {f.name: f for f in dataclasses.fields(base)}, _hints(base)
    unknown = sorted(set(changes) - set(fields))
    if unknown:
        raise ValueError(f"derive: {base.__name__} has no field {unknown[0]!r}; its fields: "
                         f"{', '.join(fields)}")
    new = [(key, hints[key], change if isinstance(change, dataclasses.Field)
            else dataclasses.field(default=change, metadata=fields[key].metadata))
           for key, change in changes.items()]
    module = sys._getframe(1).f_globals["__name__"]
    return dataclasses.make_dataclass(name, new, bases=(base,), frozen=True,
                                      namespace={"__doc__": doc, "__module__": module})


def tree(name: str, doc: str, validate=None, module: str | None = None, **sections) -> type:
    """A frozen :class:`Section` ``name`` whose fields are the given sections (``key=Class``), in
    that order, each defaulting to its class's defaults; ``validate(self)``, when given, checks
    what spans several sections. The class belongs to ``module`` (default: the calling one)."""
    namespace = {"__doc__": doc, "__module__": module or sys._getframe(1).f_globals["__name__"]}
    if validate is not None:
        namespace["validate"] = validate
    return dataclasses.make_dataclass(name, [(key, cls, section(cls)) for key, cls in sections.items()],
                                      bases=(Section,), frozen=True, namespace=namespace)


def from_dict(cls, data: dict | None, prefix: str = ""):
    """Build the dataclass ``cls`` from a nested dict, validating every key and value (errors name
    the dotted key, ``prefix`` + field name)."""
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ParamError(f"{prefix.rstrip('.') or 'scene'}: expected a table of parameters, got {data!r}")
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = [k for k in data if k not in fields]
    renamed = getattr(cls, "renamed", {})
    for key in unknown:
        if key in renamed:
            new = " and ".join(prefix + part for part in renamed[key].split(" and "))
            raise ParamError(f"parameter '{prefix}{key}' was renamed; use {new}")
    if unknown:
        raise ParamError(f"unknown parameter '{prefix}{unknown[0]}'; allowed keys here: "
                         f"{', '.join(prefix + k for k in fields)}")
    kwargs = {}
    for name, f in fields.items():
        if name not in data:
            continue
        ftype = hints[name]
        if dataclasses.is_dataclass(ftype):
            kwargs[name] = from_dict(ftype, data[name], f"{prefix}{name}.")
        else:
            kwargs[name] = _check_value(prefix + name, data[name], ftype, f.metadata)
    return cls(**kwargs)  # Section.__post_init__ runs validate()


def to_dict(obj) -> dict:
    """Nested plain dict of a parameter dataclass (for summary files)."""
    return dataclasses.asdict(obj)


def parse_value(text: str) -> Any:
    """A command-line value as a TOML literal (``1e-3``, ``true``, ``"E2"``); bare words stay strings."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_dotted(data: dict, key: str, value: Any) -> None:
    """``data['a']['b'] = value`` for ``key = 'a.b'``, creating intermediate tables."""
    parts = key.split(".")
    if not all(parts):
        raise ParamError(f"malformed parameter key {key!r}; use dotted names like fluid.viscosity")
    node = data
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ParamError(f"'{key}': '{part}' is a value, not a section")
    node[parts[-1]] = value


def describe(cls, prefix: str = "") -> list[tuple[str, str, str, str]]:
    """Rows ``(dotted key, default, unit, doc)`` for every parameter of ``cls`` (for the docs)."""
    rows = []
    hints = _hints(cls)
    default = cls()
    for f in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[f.name]):
            rows.extend(describe(hints[f.name], f"{prefix}{f.name}."))
        else:
            doc = f.metadata.get("doc", "")
            if f.metadata.get("choices"):
                doc += " (one of " + ", ".join(map(str, f.metadata["choices"])) + ")"
            rows.append((prefix + f.name, repr(getattr(default, f.name)), f.metadata.get("unit", ""), doc))
    return rows
