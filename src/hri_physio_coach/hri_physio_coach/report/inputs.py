"""Which bag to read and where the report goes: a session folder, a bag directory or an .mcap file.

* a session folder (``sessions/<participant>_<date-time>/``) holds one bag directory; the report
  is written into the folder, next to its ``configs/*.yaml`` (shown in the HTML page, and read
  for the coach's ``hr_topic`` and plausible HR range);
* a bag directory (``metadata.yaml`` and/or ``*.mcap``): the report goes to its parent folder;
* an ``.mcap`` file: to the parent of its bag directory (the folder holding it otherwise).

``--out`` moves the report elsewhere; the configurations are still read next to the bag.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hri_physio_coach.report.bagdata import ReportError

METADATA_FILE = "metadata.yaml"
CONFIG_DIR = "configs"
#: Configuration files larger than this are listed, not embedded in the page.
MAX_CONFIG_BYTES = 256 * 1024


@dataclass(frozen=True)
class ReportInput:
    bag: Path
    out_dir: Path
    configs: dict[str, str] = field(default_factory=dict)  # file name -> YAML text


def _is_bag_dir(path: Path) -> bool:
    return path.is_dir() and ((path / METADATA_FILE).is_file() or any(path.glob("*.mcap")))


def resolve(path: Path, out: Path | None = None) -> ReportInput:
    path = Path(path)
    if not path.exists():
        raise ReportError(f"{path} does not exist")
    if path.is_file():
        if path.suffix != ".mcap":
            raise ReportError(f"{path} is neither a session folder, a bag directory nor an .mcap file")
        folder = path.parent
        in_bag_dir = (folder / METADATA_FILE).is_file() or path.stem.startswith(folder.name)
        default_out = folder.parent if in_bag_dir else folder
        bag = path
    elif _is_bag_dir(path):
        bag, default_out = path, path.parent
    else:
        bags = sorted(p for p in path.iterdir() if _is_bag_dir(p))
        if not bags:
            raise ReportError(f"{path} holds no bag (no directory with {METADATA_FILE} or an .mcap file)")
        if len(bags) > 1:
            names = ", ".join(p.name for p in bags)
            raise ReportError(f"{path} holds {len(bags)} bags ({names}): name the one to report on")
        bag, default_out = bags[0], path
    out_dir = Path(out) if out is not None else default_out
    return ReportInput(bag, out_dir, read_configs(default_out))


def read_configs(folder: Path) -> dict[str, str]:
    """The resolved node configurations a session folder keeps (``configs/*.yaml``)."""
    directory = folder / CONFIG_DIR
    if not directory.is_dir():
        return {}
    out = {}
    for p in sorted([*directory.glob("*.yaml"), *directory.glob("*.yml")]):
        try:
            size = p.stat().st_size
            out[p.name] = (p.read_text(encoding="utf-8", errors="replace") if size <= MAX_CONFIG_BYTES
                           else f"# {size} bytes: too large to show here, see {p}")
        except OSError as exc:
            out[p.name] = f"# could not be read: {exc.strerror}"
    return out


def _find_key(node: Any, key: str) -> Iterator[Any]:
    if isinstance(node, dict):
        for k, v in node.items():
            if k == key:
                yield v
            yield from _find_key(v, key)
    elif isinstance(node, list):
        for item in node:
            yield from _find_key(item, key)


def config_value(configs: dict[str, str], key: str, prefer: str = "coach") -> tuple[Any, str] | None:
    """The first ``key`` found in the configurations (files whose name holds ``prefer`` first)."""
    names = sorted(configs, key=lambda n: (prefer not in n, n))
    for name in names:
        try:
            doc = yaml.safe_load(configs[name])
        except yaml.YAMLError:
            continue
        for value in _find_key(doc, key):
            if value is not None:
                return value, name
    return None
