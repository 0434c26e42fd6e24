"""The generic scenario engine on a fake clock, and the routine file loader."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from hri_physio_coach.engine import FINISHED, STOPPED, ActionContext, Hook, Listener, ScenarioEngine
from hri_physio_coach.routine import Action, Activity, Phase, RoutineError, load_routine, parse_routine

ROUTINE = {
    "name": "toy",
    "action_sets": {"show": [{"video": "{x}"}, {"video": "splash", "after": "preview"}]},
    "on_start": [{"volume": 50}],
    "phases": [
        {"name": "a", "hooks": ["fast", "slow"], "on_enter": [{"say": "enter a"}],
         "on_exit": [{"say": "exit a"}], "activity_actions": "show",
         "activities": [{"name": "a1", "duration": 10, "x": "v1"}, {"name": "a2", "duration": 2, "x": "v2"}]},
        {"name": "b", "kind": "rest", "activities": [{"name": "b1", "duration": "pause"}]},
        {"name": "c", "hooks": ["fast"], "activities": [{"name": "c1", "duration": 6}]},
    ],
    "on_end": [{"say": "bye"}],
}
VARIABLES = {"preview": 3.0, "pause": 5.0}


class Recorder(Listener):
    def __init__(self) -> None:
        self.log: list[tuple[float, str]] = []
        self.events: list[dict[str, Any]] = []
        self.engine: ScenarioEngine | None = None

    def sink(self, event: dict[str, Any]) -> None:
        self.events.append(event)
        if event["event"] in ("phase", "activity"):
            self.log.append((event["t"], f"{event['event']}:{event.get('activity', event['phase'])}"))
        elif event["event"] in ("hook_skipped", "session_end"):
            self.log.append((event["t"], f"{event['event']}:{event.get('hook', '')}"))

    def action(self, action: Action, ctx: ActionContext) -> None:
        value = action.value.format(x=ctx.activity.attrs.get("x", "") if ctx.activity else "")
        self.log.append((ctx.t, f"{action.kind}:{value}"))

    def hook(self, name: str):
        def run(t: float) -> None:
            assert self.engine is not None and self.engine.now == t
            self.log.append((t, f"hook:{name}"))
        return run

    def on_activity_start(self, phase: Phase, activity: Activity, t: float) -> None:
        self.log.append((t, f"listener:{activity.name}"))


def make(step_log: Recorder | None = None) -> tuple[ScenarioEngine, Recorder]:
    rec = step_log or Recorder()
    routine = parse_routine(ROUTINE, VARIABLES)
    hooks = {"fast": Hook("fast", 2.0, rec.hook("fast"), priority=10),
             "slow": Hook("slow", 3.0, rec.hook("slow"), priority=0)}
    engine = ScenarioEngine(routine, clock=lambda: 0.0, sink=rec.sink, on_action=rec.action, hooks=hooks,
                            listener=rec)
    rec.engine = engine
    return engine, rec


EXPECTED = [
    (0, "volume:50"),
    (0, "phase:a"), (0, "say:enter a"), (0, "activity:a1"), (0, "listener:a1"), (0, "video:v1"),
    (2, "hook:fast"), (3, "hook:slow"), (3, "video:splash"), (4, "hook:fast"),
    (6, "hook:fast"), (6, "hook_skipped:slow"),  # same instant: the higher priority wins
    (8, "hook:fast"), (9, "hook:slow"),
    (10, "hook:fast"),  # hooks due at a transition run before it
    (10, "activity:a2"), (10, "listener:a2"), (10, "video:v2"),  # its splash (t=13) dies with a2 at 12
    (12, "say:exit a"),  # no hook at 12: the run of phases with the hooks ends there
    (12, "phase:b"), (12, "activity:b1"), (12, "listener:b1"),
    (17, "phase:c"), (17, "activity:c1"), (17, "listener:c1"),
    (19, "hook:fast"), (21, "hook:fast"),  # re-anchored at c's start; none at the session end (23)
    (23, "say:bye"), (23, "session_end:"),
]


def test_sequence_and_timing_on_a_fake_clock() -> None:
    engine, rec = make()
    engine.start(0.0)
    engine.tick(100.0)  # one call: every timer still fires at its own time, in order
    assert engine.state == FINISHED
    assert rec.log == EXPECTED
    assert engine.routine.duration == 23.0


@pytest.mark.parametrize("step", [0.1, 0.7, 1.0, 5.0])
def test_tick_granularity_does_not_change_anything(step: float) -> None:
    engine, rec = make()
    engine.run_to_end(step=step)
    assert rec.log == EXPECTED


def test_a_gate_holds_an_instant_and_everything_after_it_until_it_opens_or_its_time_comes() -> None:
    """The hook and the transition due at 10 s wait for the gate; when they run they carry 10 s."""
    engine, rec = make()
    ready = {"at": None}

    def gate(t: float) -> float | None:
        return None if t != 10.0 or ready["at"] is not None else 13.0

    engine.gate = gate
    engine.start(0.0)
    engine.tick(11.5)
    assert rec.log == EXPECTED[:EXPECTED.index((10, "hook:fast"))]
    assert engine.now == 10.0 and engine.held_at == 10.0  # time stands at the held instant
    assert engine.next_due() == 13.0  # the latest the gate holds it: a driver wakes then (or sooner)
    ready["at"] = 11.8
    engine.tick(11.8)
    assert engine.held_at is None and engine.now == 11.8
    engine.tick(100.0)
    assert rec.log == EXPECTED  # every time as without the gate


def test_a_gate_that_never_opens_holds_until_the_time_it_names() -> None:
    engine, rec = make()
    engine.gate = lambda t: 13.0 if t == 10.0 else None
    engine.start(0.0)
    engine.tick(12.9)
    assert engine.held_at == 10.0 and (10, "hook:fast") not in rec.log
    engine.tick(13.0)
    assert engine.held_at is None
    engine.tick(100.0)
    assert rec.log == EXPECTED


def test_events_describe_the_session() -> None:
    engine, rec = make()
    engine.start(1000.0)  # any start time: everything is relative to it
    engine.tick(2000.0)
    kinds = [e["event"] for e in rec.events]
    assert kinds[0] == "session_start" and kinds[-1] == "session_end"
    start = rec.events[0]
    assert start["t"] == 1000.0 and start["ends_at"] == 1023.0 and start["phases"] == ["a", "b", "c"]
    acts = [e for e in rec.events if e["event"] == "activity"]
    assert [(e["t"], e["activity"], e["ends_at"]) for e in acts] == [
        (1000.0, "a1", 1010.0), (1010.0, "a2", 1012.0), (1012.0, "b1", 1017.0), (1017.0, "c1", 1023.0)]
    assert acts[0]["x"] == "v1"  # activity attributes travel in the event
    phase_b = next(e for e in rec.events if e["event"] == "phase" and e["phase"] == "b")
    assert phase_b["kind"] == "rest" and phase_b["duration"] == 5.0
    skipped = [e for e in rec.events if e["event"] == "hook_skipped"]
    assert skipped == [{"t": 1006.0, "event": "hook_skipped", "hook": "slow", "winner": "fast",
                        "reason": "fast has priority in the same tick"}]


def test_state_and_stop() -> None:
    engine, rec = make()
    assert engine.state == "idle"
    engine.start(0.0)
    engine.tick(10.5)
    state = engine.state_dict()
    assert (state["phase"], state["activity"], state["activity_ends_at"]) == ("a", "a2", 12.0)
    engine.stop("operator")
    assert engine.state == STOPPED
    assert rec.events[-1]["event"] == "session_stopped" and rec.events[-1]["reason"] == "operator"
    n = len(rec.log)
    engine.tick(100.0)
    assert len(rec.log) == n  # nothing runs after a stop
    with pytest.raises(RuntimeError):
        engine.start()


def test_time_going_backwards_is_ignored() -> None:
    engine, rec = make()
    engine.start(0.0)
    engine.tick(5.0)
    n = len(rec.log)
    engine.tick(1.0)
    assert len(rec.log) == n and engine.now == 5.0


def test_unknown_hook_is_an_error() -> None:
    routine = parse_routine(ROUTINE, VARIABLES)
    with pytest.raises(ValueError, match=r"uses hook\(s\) \['slow'\]"):
        ScenarioEngine(routine, lambda: 0.0, lambda e: None, lambda a, c: None,
                       hooks={"fast": Hook("fast", 1.0, lambda t: None)})
    with pytest.raises(ValueError, match="period"):
        Hook("x", 0.0, lambda t: None)


def test_without_phases() -> None:
    routine = parse_routine(ROUTINE, VARIABLES)
    assert [p.name for p in routine.without(["b"]).phases] == ["a", "c"]
    assert [p.name for p in routine.without(["rest"]).phases] == ["a", "c"]  # by kind too
    with pytest.raises(RoutineError, match="leaves no phase"):
        routine.without(["a", "b", "c"])


@pytest.mark.parametrize(
    "change,match",
    [
        ({"phases": []}, "'phases' must be a non-empty list"),
        ({"phases": [{"name": "p", "activities": []}]}, "'activities' must be a non-empty list"),
        ({"phases": [{"name": "p", "activities": [{"name": "x"}]}]}, "missing 'duration'"),
        ({"phases": [{"name": "p", "activities": [{"name": "x", "duration": -3}]}]}, "duration must be"),
        ({"phases": [{"name": "p", "activities": [{"name": "x", "duration": "calib"}]}]},
         "neither a number nor a known variable"),
        ({"phases": [{"name": "p", "activities": [{"name": "x", "duration": 1}]},
                     {"name": "p", "activities": [{"name": "y", "duration": 1}]}]}, "duplicate phase name"),
        ({"phases": [{"name": "p", "colour": "red", "activities": [{"name": "x", "duration": 1}]}]},
         r"unknown key\(s\) \['colour'\]"),
        ({"on_end": [{"sing": "la"}]}, "exactly one of"),
        ({"on_end": [{"say": "a", "video": "b"}]}, "exactly one of"),
        ({"on_end": [{"say": "a", "after": -1}]}, "after must be"),
        ({"on_end": [{"say": None}]}, "needs a text"),
        ({"on_end": "bye"}, "not a known action set"),
        ({"phases": [{"name": "p", "activity_actions": "nope",
                      "activities": [{"name": "x", "duration": 1}]}]},
         "'nope' is not a known action set"),
        ({"stages": []}, r"unknown key\(s\) \['stages'\]"),
    ],
)
def test_routine_errors(change: dict, match: str) -> None:
    with pytest.raises(RoutineError, match=match):
        parse_routine({**ROUTINE, **change}, VARIABLES, source="toy.yaml")


def test_load_routine_file_errors(tmp_path: Path) -> None:
    with pytest.raises(RoutineError, match="does not exist"):
        load_routine(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("phases: [\n  - name: x\n")
    with pytest.raises(RoutineError, match="not valid YAML at line"):
        load_routine(bad)


def test_an_unquoted_comma_in_a_flow_mapping_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "comma.yaml"
    bad.write_text("name: r\nphases:\n  - name: p\n    activities:\n"
                   "      - {name: a, label: step-up, reach and pull, duration: 10}\n")
    with pytest.raises(RoutineError, match=r"activity 'a': 'reach and pull' has no value.*quote the value"):
        load_routine(bad)


def test_the_packaged_routine_labels_are_whole() -> None:
    from hri_physio_coach.coach import load_coach_routine
    from hri_physio_coach.config import CoachConfig

    routine = load_coach_routine(CoachConfig())
    labels = {a.label for p in routine.phases for a in p.activities}
    assert "step-up, reach and pull" in labels and "step-up" not in labels
