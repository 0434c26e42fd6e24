"""Message definitions and type hashes from the installed interface packages.

rosbag2's MCAP storage stores, per schema, the full ``.msg`` text of the type followed by
the text of every type it uses, each introduced by a line of 80 ``=`` and ``MSG: pkg/Type``
(the ``ros2msg`` schema encoding that Foxglove, ``rosbags`` and ``ros2 bag`` all parse).
This module builds that text from ``<prefix>/share/<pkg>/msg/<Type>.msg`` along the
``AMENT_PREFIX_PATH``, and reads the RIHS01 type-description hash that rosidl generated
next to it (``<Type>.json``): an independent source to check the hashes the ROS graph reports.
"""

from __future__ import annotations

import importlib
import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hri_physio_bridge.bag.errors import BagError

SEPARATOR = "=" * 80
PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    }
)
_TYPE_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(?:(msg|srv|action)/)?([A-Za-z][A-Za-z0-9_]*)$")


class UnknownTypeError(BagError):
    """The message type (its Python module or its definition) is not installed here."""


@dataclass(frozen=True)
class TypeName:
    package: str
    interface: str  # "msg" (srv/action types only appear as their generated messages)
    name: str

    @classmethod
    def parse(cls, text: str) -> TypeName:
        m = _TYPE_RE.match(text.strip())
        if not m:
            raise UnknownTypeError(f"{text!r} is not a ROS 2 type name like 'std_msgs/msg/String'")
        return cls(m.group(1), m.group(2) or "msg", m.group(3))

    @property
    def full(self) -> str:
        return f"{self.package}/{self.interface}/{self.name}"

    @property
    def short(self) -> str:
        return f"{self.package}/{self.name}"


def search_prefixes(env: dict[str, str] | None = None) -> list[Path]:
    env = os.environ if env is None else env
    return [Path(p) for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]


def _find(tn: TypeName, suffix: str, prefixes: Sequence[Path]) -> Path | None:
    for prefix in prefixes:
        path = prefix / "share" / tn.package / tn.interface / f"{tn.name}{suffix}"
        if path.is_file():
            return path
    return None


def msg_dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of a ``.msg`` text, as ``pkg/Type``, sorted, unique."""
    deps: set[str] = set()
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        field_type = line.split()[0]
        base = re.split(r"[\[<]", field_type, maxsplit=1)[0]
        if base in PRIMITIVES:
            continue
        deps.add(base if "/" in base else f"{package}/{base}")
    return sorted(deps)


def message_definition(type_name: str, prefixes: Sequence[Path] | None = None) -> str:
    """The full ``ros2msg`` schema text of ``type_name`` (dependencies depth-first, once each)."""
    prefixes = search_prefixes() if prefixes is None else prefixes
    seen: set[str] = set()

    def expand(tn: TypeName, depth: int) -> str:
        if depth > 50:
            raise UnknownTypeError(f"definition of {type_name} nests deeper than 50 levels")
        path = _find(tn, ".msg", prefixes)
        if path is None:
            raise UnknownTypeError(
                f"no definition {tn.package}/{tn.interface}/{tn.name}.msg under AMENT_PREFIX_PATH"
            )
        text = path.read_text(encoding="utf-8")
        out = text
        for dep in msg_dependencies(text, tn.package):
            if dep in seen:
                continue
            seen.add(dep)
            out += f"\n{SEPARATOR}\nMSG: {dep}\n" + expand(TypeName.parse(dep), depth + 1)
        return out

    return expand(TypeName.parse(type_name), 0)


def installed_type_hash(type_name: str, prefixes: Sequence[Path] | None = None) -> str | None:
    """The RIHS01 hash rosidl generated for ``type_name`` (``None`` if not installed)."""
    prefixes = search_prefixes() if prefixes is None else prefixes
    tn = TypeName.parse(type_name)
    path = _find(tn, ".json", prefixes)
    if path is None:
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == tn.full:
            return str(entry.get("hash_string"))
    return None


def import_message_type(type_name: str) -> Any:
    """The generated Python class of ``type_name`` (``std_msgs/msg/String`` -> ``String``)."""
    tn = TypeName.parse(type_name)
    try:
        module = importlib.import_module(f"{tn.package}.{tn.interface}")
        return getattr(module, tn.name)
    except (ImportError, AttributeError):
        raise UnknownTypeError(
            f"message type {tn.full} is not installed (no Python module {tn.package}.{tn.interface})"
        ) from None
