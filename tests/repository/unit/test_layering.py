"""The layering rule cannot be bypassed by forgetting a module: every module is classified, once.

``.importlinter`` is the one list: its "logic" contract names the logic modules (``lint-imports`` in
scripts/test checks that they import no ROS, LSL or BLE runtime) and its ``[layering]`` section
names the runtime shells (nodes, launchers, transports). A new module must be put in exactly one of
the two; an entry that names no module (a module that was moved or removed) is an error too.
"""

from __future__ import annotations

import configparser
import fnmatch

from helpers import ROOT, SRC


def _config() -> configparser.ConfigParser:
    parser = configparser.ConfigParser()
    parser.read(ROOT / ".importlinter")
    return parser


def _lines(text: str) -> list[str]:
    return [line.strip() for line in text.replace("|", "\n").splitlines() if line.strip()]


def _modules() -> list[str]:
    """Every module and subpackage of the packages under src/ (the top-level packages themselves excepted)."""
    found = []
    for init in sorted(SRC.glob("*/*/__init__.py")):
        package = init.parent
        if package.parent.name != package.name:
            continue
        for path in sorted(package.rglob("*.py")):
            parts = path.relative_to(package.parent).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if len(parts) > 1:
                found.append(".".join(parts))
    return found


def test_every_module_is_logic_or_a_runtime_shell() -> None:
    config = _config()
    logic = _lines(config["importlinter:contract:logic"]["source_modules"])
    shells = _lines(config["layering"]["runtime_shells"])
    roots = set(_lines(config["importlinter:contract:packages"]["layers"]))
    unclassified = []
    for module in _modules():
        if module.split(".")[0] not in roots:
            unclassified.append(f"{module} (its package is in no layer of the 'packages' contract)")
            continue
        in_logic = any(module == m or module.startswith(m + ".") for m in logic)
        in_shell = any(fnmatch.fnmatch(module, p) for p in shells)
        if in_logic == in_shell:
            where = "both lists" if in_logic else "neither list"
            unclassified.append(f"{module} ({where})")
    assert not unclassified, (
        "classify each module once in .importlinter: logic -> [importlinter:contract:logic] source_modules, "
        "runtime shell -> [layering] runtime_shells:\n  " + "\n  ".join(unclassified)
    )


def test_every_entry_of_the_lists_names_a_module_that_exists() -> None:
    config = _config()
    modules = set(_modules())
    entries = (_lines(config["importlinter:contract:logic"]["source_modules"])
               + _lines(config["layering"]["runtime_shells"]))
    stale = [e for e in entries if not any(m == e or m.startswith(e + ".") or fnmatch.fnmatch(m, e)
                                           for m in modules)]
    assert not stale, f"entries of .importlinter that name no module under src/: {stale}"


def test_every_package_is_in_the_packages_contract() -> None:
    packages = {p.parent.name for p in SRC.glob("*/package.xml")}
    config = _config()
    assert set(_lines(config["importlinter:contract:packages"]["layers"])) == packages
    assert set(_lines(config["importlinter"]["root_packages"])) == packages
