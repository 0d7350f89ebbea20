"""Settings dataclasses: presets in JSON files, ``key=value`` overrides, strict checking.

Each stage has one frozen-ish dataclass of settings with a comment on every field. This module
turns a JSON preset plus command-line overrides into an instance, rejecting unknown keys and values
of the wrong type (nanoGPT's configurator behaviour without ``exec``). The resolved settings are
saved next to every output with :func:`settings_to_dict`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from neuralao.runtime.foundation.errors import NeuralaoError
from neuralao.runtime.foundation.limits import FLOAT32_MAX, FLOAT32_TINY
from neuralao.runtime.foundation.manifest import parse_json, read_json

T = TypeVar("T")


def _coerce(name: str, value: Any, tp: Any) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(name, value, a)
            except NeuralaoError as e:
                errors.append(str(e))
        raise NeuralaoError(f"setting {name!r}: {value!r} does not match {tp}")
    if origin is typing.Literal:
        if value not in args:
            raise NeuralaoError(f"setting {name!r}: {value!r} is not one of {list(args)}")
        return value
    if origin in (list, tuple):
        if not isinstance(value, list | tuple):
            raise NeuralaoError(f"setting {name!r}: expected a list, got {value!r}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise NeuralaoError(f"setting {name!r}: expected {len(args)} values, got {len(value)}")
            return tuple(_coerce(name, v, a) for v, a in zip(value, args, strict=True))
        inner = args[0] if args else Any
        seq = [_coerce(name, v, inner) for v in value]
        return tuple(seq) if origin is tuple else seq
    if origin is dict:
        if not isinstance(value, dict):
            raise NeuralaoError(f"setting {name!r}: expected a mapping, got {value!r}")
        return dict(value)
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise NeuralaoError(f"setting {name!r}: expected a mapping, got {value!r}")
        return from_dict(tp, value, prefix=f"{name}.")
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise NeuralaoError(f"setting {name!r}: expected true/false, got {value!r}")
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise NeuralaoError(f"setting {name!r}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise NeuralaoError(f"setting {name!r}: expected a number, got {value!r}")
        # NaN or inf is no setting's meaning, and a value past float32 becomes inf where it is used (one
        # below its smallest normal, 0 or a subnormal): refused here, before any work, naming the setting
        if not math.isfinite(value) or abs(value) > FLOAT32_MAX or 0 < abs(value) < FLOAT32_TINY:
            raise NeuralaoError(
                f"setting {name!r}: {value!r} is not a finite number float32 holds "
                f"(0, or {FLOAT32_TINY:.4g} <= |x| <= {FLOAT32_MAX:.4g})"
            )
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise NeuralaoError(f"setting {name!r}: expected a string, got {value!r}")
        return value
    return value


def from_dict(cls: type[T], data: dict[str, Any], prefix: str = "") -> T:
    """Build ``cls`` from a mapping; unknown keys and wrong types raise :class:`NeuralaoError`."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise NeuralaoError(
            f"unknown setting(s) {', '.join(prefix + u for u in unknown)} for {cls.__name__}; "
            f"known: {', '.join(sorted(fields))}"
        )
    kwargs = {k: _coerce(prefix + k, v, hints[k]) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except TypeError as e:
        raise NeuralaoError(f"{cls.__name__}: {e}") from None


def parse_override(text: str) -> tuple[str, Any]:
    """``key=value`` with a JSON value (bare words are strings): ``rays=64``, ``kernel=binary``."""
    if "=" not in text:
        raise NeuralaoError(f"override {text!r} is not key=value")
    key, raw = text.split("=", 1)
    try:
        value = parse_json(raw, f"override {key.strip()!r}", "value")
    except NeuralaoError as e:
        if "not valid JSON" not in str(e):
            raise  # too deep or too big: not a bare word either
        value = raw
    return key.strip(), value


def load_settings(cls: type[T], preset: str | Path | None = None, overrides: list[str] | None = None) -> T:
    """Preset file (JSON) -> dict, apply ``key=value`` overrides (dotted keys nest), build ``cls``."""
    data: dict[str, Any] = {}
    if preset is not None:
        path = Path(preset)
        data = read_json(path, "config file")
        if not isinstance(data, dict):
            raise NeuralaoError(f"config file {path} must hold a JSON object")
        try:  # the file alone first, so a refusal of what it holds names it
            from_dict(cls, json.loads(json.dumps(data)))
        except NeuralaoError as e:
            raise NeuralaoError(f"config file {path}: {e}") from None
    return from_dict(cls, apply_overrides(data, overrides))


def apply_overrides(data: dict[str, Any], overrides: list[str] | None) -> dict[str, Any]:
    """Apply ``key=value`` overrides to ``data`` in place (dotted keys nest); returns ``data``."""
    for item in overrides or []:
        key, value = parse_override(item)
        node: Any = data
        parts = key.split(".")
        for depth, p in enumerate(parts):
            last = depth == len(parts) - 1
            if isinstance(node, list):  # a list entry by index: scenes.0.views=4
                if not (p.isdigit() and int(p) < len(node)):
                    where = ".".join(parts[:depth]) or "the settings"
                    raise NeuralaoError(
                        f"override {key!r}: {where} is a list of {len(node)}; {p!r} is not an index in it"
                    )
                p = int(p)
            elif not isinstance(node, dict):
                raise NeuralaoError(f"override {key!r}: {'.'.join(parts[:depth])} is not a mapping")
            if last:
                node[p] = value
            else:
                node = node.setdefault(p, {}) if isinstance(node, dict) else node[p]
    return data


def settings_to_dict(settings: Any) -> dict[str, Any]:
    """Resolved settings as plain JSON-able data (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(settings), default=str))


def add_set_option(parser: argparse.ArgumentParser, example: str) -> None:
    """The ``--set KEY=VALUE`` option every command with settings takes (read by :func:`load_settings`)."""
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override a setting (repeatable; unknown keys and wrong types are rejected), e.g. {example}",
    )
