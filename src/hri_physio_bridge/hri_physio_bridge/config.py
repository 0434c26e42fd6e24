"""One configuration model for every node: options declared once, everything else derived.

A node's options are a :class:`NodeConfig` subclass (pydantic v2): each field has a type, a
default that runs without hardware, a help text, optionally a unit and bounds. From that one
declaration come

- the command-line flags and the ``--help`` text (:func:`add_config_arguments`),
- the ``--conf`` YAML file (:func:`load_yaml`, flat or a ROS params file; the seed's keys are
  translated by :meth:`NodeConfig.translate_keys`),
- the ROS parameters with their descriptions and ranges (``node_runner.declare_config``),
- the validation messages (:class:`ConfigError`, one line naming the option).

Nothing here imports rclpy: a configuration can be checked before any node starts.
"""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal, NoReturn, Self, TypeVar, get_args, get_origin

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic.fields import FieldInfo

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration problem, said in one line that names the option and what it expects."""


# ----------------------------------------------------------------------------------------------
# YAML
def load_yaml(path: str | Path, node_name: str | None = None) -> dict[str, Any]:
    """The options in a YAML file: flat ``key: value`` pairs (the seed's format) or a ROS params file.

    From a ROS params file (``<node>: {ros__parameters: {...}}`` or ``/**: ...``) the section of
    ``node_name`` (or ``/**``) is taken, so one file serves ``--conf`` and ``--params-file``.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"configuration file {p} does not exist")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"configuration file {p} is not UTF-8 text (byte {exc.start})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"configuration file {p} is not valid YAML{where}: {problem}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"configuration file {p} must hold key: value pairs, not {type(data).__name__}")
    for key in (node_name, f"/{node_name}" if node_name else None, "/**"):
        section = data.get(key) if key else None
        if isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict):
            return dict(section["ros__parameters"])
    return {str(k): v for k, v in data.items()}


# ----------------------------------------------------------------------------------------------
# Field declaration
def option(
    default: Any,
    help: str,
    *,
    unit: str | None = None,
    switch: bool = False,
    dynamic: bool = False,
    **constraints: Any,
) -> Any:
    """A field with its help text, unit and bounds (``ge``, ``gt``, ``le``, ``lt``, ...).

    ``switch=True`` makes the command-line flag a bare switch (``--interactive``) instead of
    ``--interactive true``. ``dynamic=True`` marks an option the node applies when its ROS
    parameter is set at run time (the node's ``apply_config``); every other option's parameter
    is read-only, so a change the node would not apply is refused instead of silently ignored.
    """
    extra = {"unit": unit, "switch": switch, "dynamic": dynamic}
    if isinstance(default, list):
        return Field(default_factory=lambda d=default: list(d), description=help,
                     json_schema_extra=extra, **constraints)
    return Field(default, description=help, json_schema_extra=extra, **constraints)


def _extra(info: FieldInfo) -> dict[str, Any]:
    extra = info.json_schema_extra
    return extra if isinstance(extra, dict) else {}


def _strip_optional(annotation: Any) -> Any:
    if get_origin(annotation) in (typing.Union, types.UnionType):
        args = [a for a in get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return annotation


def _kind(annotation: Any) -> str:
    """bool | int | float | str | list | choice: how a field is written on the command line."""
    annotation = _strip_optional(annotation)
    if get_origin(annotation) is Literal:
        return "choice"
    if get_origin(annotation) in (list, tuple) or annotation in (list, tuple):
        return "list"
    for name, kind in (("bool", bool), ("int", int), ("float", float)):
        if annotation is kind:
            return name
    return "str"


def _bounds(info: FieldInfo) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for meta in info.metadata:
        for key in ("ge", "gt", "le", "lt", "min_length", "max_length"):
            value = getattr(meta, key, None)
            if value is not None:
                out[key] = value
    return out


def describe_bounds(info: FieldInfo) -> str:
    """The bounds of a field as text, e.g. ``>= 1``, ``0 < x <= 1``."""
    b = _bounds(info)
    low = f">= {b['ge']:g}" if "ge" in b else f"> {b['gt']:g}" if "gt" in b else ""
    high = f"<= {b['le']:g}" if "le" in b else f"< {b['lt']:g}" if "lt" in b else ""
    return ", ".join(part for part in (low, high) if part)


class NodeConfig(BaseModel):
    """Base of every node's options. Subclass it and declare fields with :func:`option`."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, coerce_numbers_to_str=True, allow_inf_nan=False,
        validate_default=True,
    )

    #: The seed's keys this node also accepts in ``--conf`` files (documentation and help).
    SEED_KEYS: ClassVar[tuple[str, ...]] = ()

    @model_validator(mode="before")
    @classmethod
    def _normalise(cls, data: Any) -> Any:
        """Comma-separated text for list options; no booleans where numbers are expected."""
        if not isinstance(data, Mapping):
            return data
        out = dict(data)
        for name, info in cls.model_fields.items():
            if name not in out:
                continue
            value, kind = out[name], _kind(info.annotation)
            if kind == "list" and isinstance(value, str):
                out[name] = [v.strip() for v in value.split(",") if v.strip()]
            elif kind == "list" and isinstance(value, bytes | bytearray) and not value:
                out[name] = []  # rclpy declares an empty list as an empty byte array
            elif kind in ("int", "float") and isinstance(value, bool):
                raise ValueError(f"{name}: expected a number, got {value!r}")
            elif value == "" and info.default is None:
                out[name] = None
        return out

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def translate_keys(cls, data: dict[str, Any], source: str) -> dict[str, Any]:
        """Rename or convert the seed's keys (override in subclasses that accept them)."""
        return data

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "configuration") -> Self:
        """A validated configuration from flat key/value pairs; :class:`ConfigError` otherwise."""
        data = {str(k).replace("-", "_"): v for k, v in values.items()}
        data = cls.translate_keys(data, source)
        unknown = sorted(set(data) - set(cls.model_fields))
        if unknown:
            raise ConfigError(
                f"{source}: unknown option(s) {', '.join(unknown)}; known: {', '.join(cls.model_fields)}"
            )
        try:
            return cls(**data)
        except ValidationError as exc:
            raise ConfigError(f"{source}: {_first_error(exc)}") from None
        except ValueError as exc:
            raise ConfigError(f"{source}: {exc}") from None

    @classmethod
    def from_file(cls, path: str | Path, node_name: str | None = None,
                  overrides: Mapping[str, Any] | None = None) -> Self:
        """Defaults < the YAML file < ``overrides``, validated."""
        values = load_yaml(path, node_name)
        values.update(overrides or {})
        return cls.from_mapping(values, str(path))

    def replace(self, **changes: Any) -> Self:
        """A validated copy with ``changes`` applied."""
        return type(self).from_mapping({**self.as_dict(), **changes}, "configuration")

    def as_dict(self) -> dict[str, Any]:
        return self.model_dump()

    def settings(self, cls: type[T], **overrides: Any) -> T:
        """A logic module's settings dataclass ``cls`` from the options of the same names, plus ``overrides``.

        Options the dataclass does not have are left out; its fields without an option keep their defaults.
        """
        names = {f.name for f in dataclasses.fields(cls)} - overrides.keys()
        values = {name: getattr(self, name) for name in names if name in type(self).model_fields}
        return cls(**values, **overrides)

    def to_yaml(self, node_name: str | None = None) -> str:
        """The resolved options as YAML (a ROS params file when ``node_name`` is given)."""
        data: dict[str, Any] = self.model_dump(mode="json")
        if node_name:
            data = {node_name: {"ros__parameters": data}}
        return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)

    # --- introspection ------------------------------------------------------------------------
    @classmethod
    def describe(cls, name: str) -> str:
        """The help text of one option with its unit, bounds and default."""
        info = cls.model_fields[name]
        text = info.description or ""
        unit = _extra(info).get("unit")
        bounds = describe_bounds(info)
        if unit:
            text += f" [{unit}]"
        if bounds:
            text += f" ({bounds})"
        if _extra(info).get("dynamic"):
            text += " (settable at run time)"
        default = info.get_default(call_default_factory=True)
        if isinstance(default, list):
            default = ",".join(str(v) for v in default)
        return f"{text} (default: {default!r})"

    @classmethod
    def help_text(cls, name: str) -> str:
        """:meth:`describe` escaped for argparse (which formats help with ``%``)."""
        return cls.describe(name).replace("%", "%%")

    @classmethod
    def is_dynamic(cls, name: str) -> bool:
        """True when the node applies a change of this option at run time (``option(..., dynamic=True)``)."""
        return bool(_extra(cls.model_fields[name]).get("dynamic"))

    @classmethod
    def dynamic_options(cls) -> tuple[str, ...]:
        return tuple(name for name in cls.model_fields if cls.is_dynamic(name))

    @classmethod
    def kind(cls, name: str) -> str:
        return _kind(cls.model_fields[name].annotation)

    @classmethod
    def bounds(cls, name: str) -> dict[str, Any]:
        return _bounds(cls.model_fields[name])


def _first_error(exc: ValidationError) -> str:
    """The first validation problem as ``<option>: <what it expects> (got <value>)``."""
    err = exc.errors(include_url=False)[0]
    loc = ".".join(str(part) for part in err.get("loc", ()) if part != "__root__")
    msg = err.get("msg", "invalid value")
    if msg.startswith("Input should be "):
        msg = "expected " + msg.removeprefix("Input should be ")
    msg = msg.removeprefix("Value error, ")
    if not loc:
        return msg
    value = err.get("input")
    got = "" if isinstance(value, Mapping) else f" (got {value!r})"
    return f"{loc}: {msg}{got}"


# ----------------------------------------------------------------------------------------------
# Command line
class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``<prog>: error: ...``, status 2), no usage dump."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


_METAVAR = {"bool": "BOOL", "int": "INT", "float": "NUM", "str": "TEXT", "list": "A,B,..."}


def add_config_arguments(parser: argparse.ArgumentParser, config_cls: type[NodeConfig],
                         skip: Iterable[str] = ()) -> None:
    """One ``--flag`` per option (``dest`` = the option's name, default None = not given).

    Values stay text here: the model converts and checks them, so a wrong value on the command
    line gets the same message as in a YAML file or a ROS parameter.
    """
    group = parser.add_argument_group("options (also --conf YAML keys and ROS parameters)")
    skipped = set(skip)
    for name, info in config_cls.model_fields.items():
        if name in skipped:
            continue
        flag = "--" + name.replace("_", "-")
        kind = _kind(info.annotation)
        if _extra(info).get("switch"):
            group.add_argument(flag, dest=name, action="store_const", const=True, default=None,
                               help=config_cls.help_text(name))
        elif kind == "choice":
            # An empty choice is the "not given" default (e.g. --role outside a lab): not offered.
            choices = [str(c) for c in get_args(_strip_optional(info.annotation)) if c != ""]
            group.add_argument(flag, dest=name, choices=choices, default=None,
                               help=config_cls.help_text(name))
        else:
            group.add_argument(flag, dest=name, default=None, metavar=_METAVAR[kind],
                               help=config_cls.help_text(name))


def given_options(args: argparse.Namespace, config_cls: type[NodeConfig]) -> dict[str, Any]:
    """The options given on the command line (flags left out are None)."""
    return {k: v for k, v in vars(args).items() if k in config_cls.model_fields and v is not None}


