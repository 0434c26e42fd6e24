"""Which activity runs in each of the routine's slots when a policy holds an activity cost.

The routine fixes the phases, the slots and their durations. A policy that picks activities
holds an activity *cost* (METs, as the routine states them); in a slot whose own activity has
another cost, the coach runs one of the routine's activities with that cost instead,
preferring the one already running (the person keeps doing what they do), then the phase's
own, then the rest of the routine's. Pure logic: the coach sends the commands and says why.
"""

from __future__ import annotations

from hri_physio_coach.routine import Activity, Phase, Routine


class ActivityChoice:
    """What runs in each slot: ``current`` (performed now), ``running`` (run in place of the slot's own)."""

    def __init__(self, routine: Routine) -> None:
        self.routine = routine
        self.current: Activity | None = None  # performed now
        self.running: Activity | None = None  # run in place of the slot's own (None: the slot's own runs)

    def levels(self, phase: Phase | None) -> tuple[float, ...]:
        """The activity costs the coach can run in ``phase`` (sorted; empty when none is stated)."""
        if phase is None:
            return ()
        return tuple(sorted({a.mets for a in self.routine.choices(phase.name) if a.mets is not None}))

    def runs_at(self, phase: Phase | None) -> tuple[tuple[str, float], ...]:
        """(name, cost) of what may run at each cost the coach can run in ``phase``: the phase's own
        activities with that cost and the one performed now if it has it (it is kept), else the
        routine's first with that cost. A policy that learns each activity predicts a cost from these."""
        if phase is None:
            return ()
        out: dict[tuple[str, float], None] = {}
        for level in self.levels(phase):
            names = [a.name for a in phase.activities if a.mets == level]
            if self.current is not None and self.current.mets == level:
                names.append(self.current.name)
            if not names:
                names = [next(a.name for a in self.routine.choices(phase.name) if a.mets == level)]
            out.update(dict.fromkeys((name, level) for name in names))
        return tuple(out)

    def _pick(self, phase: Phase, slot: Activity, level: float | None) -> Activity:
        if level is None or slot.mets is None or slot.mets == level:
            return slot
        if self.current is not None and self.current.mets == level:
            return self.current  # keep doing what you do
        return next((a for a in self.routine.choices(phase.name) if a.mets == level), slot)

    def slot_started(self, phase: Phase, slot: Activity, level: float | None) -> Activity | None:
        """A new slot: the activity run in its place (None: its own activity runs)."""
        chosen = self._pick(phase, slot, level)
        self.current = chosen
        self.running = None if chosen is slot else chosen
        return self.running

    def switch(self, phase: Phase, slot: Activity, level: float | None) -> Activity | None:
        """Mid-slot, the policy now holds ``level`` (None: the routine's): what to switch to (None: none)."""
        if level is None:
            if self.current is slot:
                return None
            self.current, self.running = slot, None
            return slot
        if self.current is None or self.current.mets == level:
            return None
        chosen = self._pick(phase, slot, level)
        if chosen is self.current or chosen.mets != level:
            return None
        self.current = chosen
        self.running = None if chosen is slot else chosen
        return chosen
