"""Typed stage parameters and engine registries (nerfstudio-style configs; docs/extending.md).

Each stage's parameters are one frozen dataclass, a subclass of :class:`StageParams`, declared in a
small ``config.py`` next to the algorithm it configures; every field is made with :func:`param`
(default, units, valid range or choices, a one-line doc). pipeline.yaml names the class in a stage's
``config:`` key; its ``params:``, the profiles and ``--set`` only override fields. The class's
``ENGINES`` registry names the stage's engines, each a callable imported only when a step runs it.

An engine's own parameters are plain fields of the stage's class whose doc starts with the engine
name (``"depth_anything: local dir or model id"``); a new engine adds its fields there and its entry
to ``ENGINES``.

Only the standard library is imported here, and config modules import only this module: the CLI,
the pipeline's validation and ``holoflow params`` never load torch.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import math
import typing
from typing import Any, Callable, ClassVar


class ParamError(ValueError):
    """A parameter value the class rejects: ``msg`` says what, ``fix`` how to correct it."""

    def __init__(self, msg: str, fix: str):
        super().__init__(f"{msg}; fix: {fix}")
        self.msg, self.fix = msg, fix


def param(
    default: Any,
    doc: str,
    units: str = "",
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: tuple[str, ...] = (),
) -> Any:
    """A stage parameter field: ``default``; ``doc`` (one line); ``units`` ("px", "m", "" for none);
    the valid range ``ge``/``gt``/``le``/``lt`` (numbers, each element of a tuple) or ``choices``."""
    meta = {"doc": doc, "units": units, "ge": ge, "gt": gt, "le": le, "lt": lt, "choices": tuple(choices)}
    return dataclasses.field(default=default, metadata=meta)


@dataclasses.dataclass(frozen=True)
class FieldInfo:
    """One parameter as ``holoflow params`` and docs/stages.md show it."""

    name: str
    type: str  # "int", "float", "bool", "str", "tuple[int, int]"
    default: Any
    units: str
    range: str  # "> 0", "[0, 1]", "grid | affine | median", "" (any)
    doc: str


class Engines:
    """A stage's engines, the one place an engine is declared: name -> ``"module:function"`` (its target,
    imported on first use, so the names can be checked without importing any engine's dependencies),
    the weights it loads, and the engine a chooser picks on a device.

    ``signature`` documents what every engine of the stage takes and returns (one per stage).
    ``choosers`` are names that stand for a registered engine picked later ({name: the rule, in
    words}: e.g. ``auto``); whoever runs the stage resolves them before ``get``. ``on_device``
    ({chooser: {device: engine}}) are the choosers the run resolves itself from its device, before
    the cache key is made (the splat stages' ``auto``: gsplat on cuda). ``weights`` ({engine: ((param,
    role), ...)}) are the models an engine loads, in load order: the stage param that names each and
    its role (a key of holoflow.networks.weights.DEFAULTS; ``holoflow models``, ``run --models``)."""

    def __init__(
        self,
        signature: str,
        choosers: dict[str, str] | None = None,
        *,
        on_device: dict[str, dict[str, str]] | None = None,
        weights: dict[str, tuple[tuple[str, str], ...]] | None = None,
        **targets: str,
    ):
        self.signature = signature
        self.choosers = dict(choosers or {})
        self.on_device = {k: dict(v) for k, v in (on_device or {}).items()}
        self.weights = {k: tuple(v) for k, v in (weights or {}).items()}
        self.targets = dict(targets)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.targets) + tuple(self.choosers)

    def for_device(self, name: str, device: str) -> str | None:
        """The engine chooser ``name`` picks on ``device``; None when ``name`` is not chosen by device."""
        return self.on_device[name].get(device) if name in self.on_device else None

    def get(self, name: str) -> Callable[..., Any]:
        """The engine callable ``name``; ValueError (one line, with the known names) if unknown."""
        if name in self.choosers:
            raise ValueError(
                f"engine {name!r} is chosen when the step runs ({self.choosers[name]}); "
                f"resolve it to one of {', '.join(self.targets)} first"
            )
        if name not in self.targets:
            raise ValueError(
                f"unknown engine {name!r}; registered: {', '.join(self.targets)}{suggest(name, self.targets)}"
            )
        module, attr = self.targets[name].split(":")
        return getattr(importlib.import_module(module), attr)


@dataclasses.dataclass(frozen=True)
class StageParams:
    """Base of every stage's parameter class (frozen: a step's params never change while it runs)."""

    ENGINES: ClassVar[Engines] = Engines("(no engines)")

    def __post_init__(self):
        """Every field checked (type, range, choices) and stored in its canonical type, however the
        instance was made: ``from_params``, or directly by a library caller."""
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, self.check(f.name, getattr(self, f.name)))

    @classmethod
    def fields_info(cls) -> list[FieldInfo]:
        hints = _hints(cls)
        return [
            FieldInfo(
                f.name,
                _type_name(hints[f.name]),
                f.default,
                f.metadata["units"],
                _range_text(f.metadata),
                f.metadata["doc"],
            )
            for f in dataclasses.fields(cls)
        ]

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """The defaults as a plain dict (the canonical form that is hashed into the cache key)."""
        return cls().as_params()

    @classmethod
    def check(cls, name: str, value: Any) -> Any:
        """``value`` for field ``name`` in its canonical type (an int for a float field -> float,
        a list for a tuple field -> tuple); ParamError for an unknown name, a wrong type or range."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        if name not in fields:
            raise ParamError(f"unknown param '{name}'", f"params are: {', '.join(fields)}{suggest(name, fields)}")
        f = fields[name]
        hint = _hints(cls)[name]
        ok, out = _coerce(hint, value)
        if not ok:
            raise ParamError(
                f"{name}={value!r} is {kind(value)}, expected {_type_name(hint)}", f"give {name} {article(hint)} value"
            )
        meta = f.metadata
        if meta["choices"] and out not in meta["choices"]:
            raise ParamError(
                f"{name}={value!r} is not one of {', '.join(meta['choices'])}",
                f"use one of: {', '.join(meta['choices'])}{suggest(str(value), meta['choices'])}",
            )
        for v in out if isinstance(out, tuple) else (out,):
            if isinstance(v, (int, float)) and not isinstance(v, bool) and not _in_range(v, meta):
                raise ParamError(
                    f"{name}={value!r} is outside the valid range {_range_text(meta)}",
                    f"give {name} a value {_range_text(meta)}",
                )
        return out

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> "StageParams":
        """An instance from a (possibly partial) mapping of overrides, every value checked."""
        names = {f.name for f in dataclasses.fields(cls)}
        for k in params:
            if k not in names:
                cls.check(k, None)  # raises: unknown param, with the names and a did-you-mean
        return cls(**params)

    def as_params(self) -> dict[str, Any]:
        """A plain, JSON-able dict of every field (tuples as lists), in field order."""
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}


def load_class(spec: str) -> type[StageParams]:
    """The class named by ``"module:Class"`` (a config module: lightweight by contract)."""
    module, _, name = spec.partition(":")
    cls = getattr(importlib.import_module(module), name, None) if name else None
    if not (isinstance(cls, type) and issubclass(cls, StageParams)):
        raise ImportError(f"{spec!r} is not a StageParams class")
    return cls


@functools.lru_cache(maxsize=None)
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def suggest(word: str, choices) -> str:
    """' (did you mean 'X'?)' for the closest of ``choices`` to ``word``, else ''."""
    import difflib

    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


def coerce_like(default: Any, value: Any) -> tuple[bool, Any]:
    """(whether ``value`` has the type of a plain ``default``, the value in that type) for a stage's
    params without a class (pipeline.yaml ``params:``): a float default takes an int (as a float), a
    list default of one element type checks each element, None takes anything."""
    if default is None:
        return True, value
    if isinstance(default, (bool, int, float, str)):
        return _coerce(type(default), value)
    if isinstance(default, list):
        if not isinstance(value, list):
            return False, value
        if default and len({type(d) for d in default}) == 1:
            pairs = [coerce_like(default[0], v) for v in value]
            return all(ok for ok, _ in pairs), [v for _, v in pairs]
        return True, value
    if isinstance(default, dict):
        return isinstance(value, dict), value
    return type(value) is type(default), value


def is_int(v: Any) -> bool:
    """An int that is not a bool."""
    return isinstance(v, int) and not isinstance(v, bool)


def _coerce(hint: Any, value: Any) -> tuple[bool, Any]:
    if hint is bool:
        return isinstance(value, bool), value
    if hint is int:
        return is_int(value), value
    if hint is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        return ok, float(value) if ok else value
    if hint is str:
        return isinstance(value, str), value
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, (list, tuple)) or len(value) != len(args):
            return False, value
        pairs = [_coerce(a, v) for a, v in zip(args, value)]
        return all(ok for ok, _ in pairs), tuple(v for _, v in pairs)
    raise TypeError(f"unsupported parameter type {hint!r}")


def _in_range(v: float, meta: dict) -> bool:
    if isinstance(v, float) and math.isnan(v):
        return False
    return (
        (meta["ge"] is None or v >= meta["ge"])
        and (meta["gt"] is None or v > meta["gt"])
        and (meta["le"] is None or v <= meta["le"])
        and (meta["lt"] is None or v < meta["lt"])
    )


def _range_text(meta: dict) -> str:
    if meta["choices"]:
        return " | ".join(meta["choices"])
    low = f">= {meta['ge']:g}" if meta["ge"] is not None else f"> {meta['gt']:g}" if meta["gt"] is not None else ""
    high = f"<= {meta['le']:g}" if meta["le"] is not None else f"< {meta['lt']:g}" if meta["lt"] is not None else ""
    return " and ".join(t for t in (low, high) if t)


def _type_name(hint: Any) -> str:
    if typing.get_origin(hint) is tuple:
        return f"tuple[{', '.join(a.__name__ for a in typing.get_args(hint))}]"
    return hint.__name__


def article(hint: Any) -> str:
    """What a value of type ``hint`` is called after "give NAME ...": "an integer", "a true/false"."""
    return {
        bool: "a true/false",
        int: "an integer",
        float: "a numeric",
        str: "a string",
        list: "a list",
        dict: "a mapping",
    }.get(hint, f"a {_type_name(hint)}")


def kind(v: Any) -> str:
    """What ``v`` is, in words ("an integer", "a mapping", "empty"), for error messages."""
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "a list",
        tuple: "a list",
        dict: "a mapping",
        type(None): "empty",
    }.get(type(v), type(v).__name__)


def _plain(v: Any) -> Any:
    return [_plain(x) for x in v] if isinstance(v, tuple) else v
