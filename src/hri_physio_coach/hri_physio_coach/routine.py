"""The data model of a scenario routine and its YAML loader (no ROS, no clock).

A routine is a list of phases; a phase is a list of activities with durations. Phases and
activities carry *actions* to run on entry (``say``, ``emotion``, ``gesture``, ``audio``,
``video``, ``volume``, or ``call`` for a scenario-specific step), each optionally delayed
with ``after: <seconds>``. A phase lists the periodic *hooks* that run while it is active
(e.g. ``rule_update``, ``behaviour``, ``reminder``) and may give ``activity_actions`` run at
the start of each of its activities (inline, or the name of an entry of ``action_sets``).

Example::

    name: my_scenario
    action_sets:
      show: [{video: "{video}"}, {video: splash, after: 30}]
    phases:
      - name: warm_up
        hooks: [rule_update]
        activity_actions: show
        activities:
          - {name: marching, duration: 180, video: marching, on_enter: [{say: "Let's march!"}]}
    on_end: [{say: Well done!}]

A duration or an ``after`` may name a variable (e.g. ``duration: calib_time``) supplied by
the scenario's configuration when the routine is loaded.

An activity may state its approximate metabolic cost, ``mets: 5.8`` (METs at the ladder's
middle tempo). Activities with a cost are the *choices* a policy that picks activities may
run in place of the routine's own, within the same phase and durations
(:meth:`Routine.choices`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

ACTION_KINDS = ("say", "emotion", "gesture", "audio", "video", "volume", "call")
_ACTIVITY_KEYS = {"name", "duration", "label", "on_enter"}
_PHASE_KEYS = {"name", "kind", "hooks", "on_enter", "on_exit", "activity_actions", "activities"}
_ROUTINE_KEYS = {"name", "action_sets", "phases", "on_start", "on_end"}


class RoutineError(ValueError):
    """A routine file that does not describe a valid routine; the message says where and why."""


@dataclass(frozen=True)
class Action:
    """One thing to do on entry: ``kind`` with its ``value``, ``after`` seconds later."""

    kind: str
    value: str
    after: float = 0.0
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Activity:
    name: str
    duration: float
    label: str = ""
    attrs: Mapping[str, Any] = field(default_factory=dict)  # any other keys: gesture, video, ...
    on_enter: tuple[Action, ...] = ()

    @property
    def mets(self) -> float | None:
        """The stated metabolic cost in METs (None: not stated, not a choice)."""
        value = self.attrs.get("mets")
        return None if value is None else float(value)


@dataclass(frozen=True)
class Phase:
    name: str
    activities: tuple[Activity, ...]
    kind: str = ""
    hooks: tuple[str, ...] = ()
    on_enter: tuple[Action, ...] = ()
    on_exit: tuple[Action, ...] = ()
    activity_actions: tuple[Action, ...] = ()

    @property
    def duration(self) -> float:
        return sum(a.duration for a in self.activities)


@dataclass(frozen=True)
class Routine:
    name: str
    phases: tuple[Phase, ...]
    on_start: tuple[Action, ...] = ()
    on_end: tuple[Action, ...] = ()

    @property
    def duration(self) -> float:
        return sum(p.duration for p in self.phases)

    def phase(self, name: str) -> Phase:
        for p in self.phases:
            if p.name == name:
                return p
        raise KeyError(name)

    def choices(self, phase: str | None = None) -> tuple[Activity, ...]:
        """Activities with a stated cost, one per name, from ``phase`` first, then the rest of the routine.

        A policy that picks activities prefers those of the phase it is in; the others serve
        when the phase has none at the cost it wants (e.g. marching in a phase of steps).
        """
        ordered = [p for p in self.phases if p.name == phase] + [p for p in self.phases if p.name != phase]
        seen: dict[str, Activity] = {}
        for p in ordered:
            for a in p.activities:
                if a.mets is not None and a.name not in seen:
                    seen[a.name] = a
        return tuple(seen.values())

    def without(self, names: Iterable[str]) -> Routine:
        """The routine with the named phases (or phase kinds) left out."""
        drop = set(names)
        kept = tuple(p for p in self.phases if p.name not in drop and p.kind not in drop)
        if not kept:
            raise RoutineError(f"routine {self.name!r}: leaving out {sorted(drop)} leaves no phase")
        return replace(self, phases=kept)


def _is_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | float) and math.isfinite(value)


def _parse_actions(raw: Any, where: str, variables: Mapping[str, float],
                   action_sets: Mapping[str, tuple[Action, ...]] | None = None) -> tuple[Action, ...]:
    if raw is None:
        return ()
    if isinstance(raw, str):
        if action_sets is not None and raw in action_sets:
            return action_sets[raw]
        known = sorted(action_sets) if action_sets else []
        raise RoutineError(f"{where}: {raw!r} is not a known action set (known: {known})")
    if not isinstance(raw, list):
        raise RoutineError(f"{where}: actions must be a list, got {type(raw).__name__}")
    out = []
    for i, item in enumerate(raw):
        here = f"{where}[{i}]"
        if not isinstance(item, dict):
            raise RoutineError(f"{here}: an action is a mapping like {{say: Hello}}, got {item!r}")
        kinds = [k for k in item if k in ACTION_KINDS]
        if len(kinds) != 1:
            raise RoutineError(
                f"{here}: an action needs exactly one of {', '.join(ACTION_KINDS)}, got keys {sorted(item)}"
            )
        kind = kinds[0]
        after = item.get("after", 0.0)
        if isinstance(after, str) and after in variables:
            after = variables[after]
        if not _is_number(after) or after < 0:
            raise RoutineError(
                f"{here}: after must be seconds >= 0 or a known variable ({sorted(variables)}), got {after!r}"
            )
        params = {k: v for k, v in item.items() if k not in (kind, "after")}
        value = item[kind]
        if value is None or isinstance(value, dict | list):
            raise RoutineError(f"{here}: {kind} needs a text or number value, got {value!r}")
        out.append(Action(kind, str(value), float(after), params))
    return tuple(out)


def _duration(raw: Any, where: str, variables: Mapping[str, float]) -> float:
    value = raw
    if isinstance(raw, str):
        if raw not in variables:
            raise RoutineError(
                f"{where}: duration {raw!r} is neither a number nor a known variable ({sorted(variables)})"
            )
        value = variables[raw]
    if not _is_number(value) or value <= 0:
        raise RoutineError(f"{where}: duration must be a number of seconds > 0, got {raw!r}")
    return float(value)


def _check_keys(raw: Mapping[str, Any], allowed: set[str], where: str) -> None:
    unknown = sorted(set(raw) - allowed)
    if unknown:
        raise RoutineError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")


def parse_routine(raw: Any, variables: Mapping[str, float] | None = None, source: str = "routine") -> Routine:
    """Build a :class:`Routine` from parsed YAML, with clear errors for anything malformed."""
    variables = dict(variables or {})
    if not isinstance(raw, dict):
        raise RoutineError(f"{source}: a routine is a mapping with 'phases', got {type(raw).__name__}")
    _check_keys(raw, _ROUTINE_KEYS, source)
    sets_raw = raw.get("action_sets") or {}
    if not isinstance(sets_raw, dict):
        raise RoutineError(f"{source}: action_sets must map names to action lists")
    action_sets = {str(k): _parse_actions(v, f"{source}: action_sets.{k}", variables)
                   for k, v in sets_raw.items()}
    phases_raw = raw.get("phases")
    if not isinstance(phases_raw, list) or not phases_raw:
        raise RoutineError(f"{source}: 'phases' must be a non-empty list")
    phases, seen = [], set()
    for i, p in enumerate(phases_raw):
        where = f"{source}: phases[{i}]"
        if not isinstance(p, dict) or not p.get("name"):
            raise RoutineError(f"{where}: a phase is a mapping with a 'name'")
        name = str(p["name"])
        where = f"{source}: phase {name!r}"
        if name in seen:
            raise RoutineError(f"{where}: duplicate phase name")
        seen.add(name)
        _check_keys(p, _PHASE_KEYS, where)
        acts_raw = p.get("activities")
        if not isinstance(acts_raw, list) or not acts_raw:
            raise RoutineError(f"{where}: 'activities' must be a non-empty list")
        activities = []
        for j, a in enumerate(acts_raw):
            if not isinstance(a, dict) or not a.get("name"):
                raise RoutineError(f"{where}: activities[{j}] is a mapping with a 'name' and a 'duration'")
            awhere = f"{where}, activity {a['name']!r}"
            if "duration" not in a:
                raise RoutineError(f"{awhere}: missing 'duration'")
            empty = [k for k, v in a.items() if v is None]
            if empty:  # e.g. {label: step-up, reach and pull}: YAML reads "reach and pull" as a key
                raise RoutineError(f"{awhere}: {', '.join(map(repr, empty))} has no value; a comma inside "
                                   "an unquoted value in {...} starts a new key: quote the value")
            mets = a.get("mets")
            if mets is not None and (not _is_number(mets) or mets < 1):
                raise RoutineError(f"{awhere}: mets must be a number >= 1 (the cost in METs), got {mets!r}")
            activities.append(Activity(
                name=str(a["name"]),
                duration=_duration(a["duration"], awhere, variables),
                label=str(a.get("label", a["name"])),
                attrs={k: v for k, v in a.items() if k not in _ACTIVITY_KEYS},
                on_enter=_parse_actions(a.get("on_enter"), f"{awhere}: on_enter", variables),
            ))
        hooks = p.get("hooks") or []
        if not isinstance(hooks, list) or not all(isinstance(h, str) for h in hooks):
            raise RoutineError(f"{where}: hooks must be a list of hook names")
        phases.append(Phase(
            name=name,
            kind=str(p.get("kind", name)),
            activities=tuple(activities),
            hooks=tuple(hooks),
            on_enter=_parse_actions(p.get("on_enter"), f"{where}: on_enter", variables),
            on_exit=_parse_actions(p.get("on_exit"), f"{where}: on_exit", variables),
            activity_actions=_parse_actions(p.get("activity_actions"), f"{where}: activity_actions",
                                            variables, action_sets),
        ))
    return Routine(
        name=str(raw.get("name", "routine")),
        phases=tuple(phases),
        on_start=_parse_actions(raw.get("on_start"), f"{source}: on_start", variables),
        on_end=_parse_actions(raw.get("on_end"), f"{source}: on_end", variables),
    )


def load_routine(path: str | Path, variables: Mapping[str, float] | None = None) -> Routine:
    """Load a routine YAML file."""
    p = Path(path)
    if not p.is_file():
        raise RoutineError(f"routine file {p} does not exist")
    try:
        raw = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise RoutineError(f"routine file {p} is not valid YAML{where}") from None
    return parse_routine(raw, variables, source=str(p))
