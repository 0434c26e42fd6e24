"""Whether a person's zone is reachable with the controls a policy has (from the participant model).

A setting (an activity at a ladder step) settles, in the participant's model, at
``params.settled_hr(activity)`` (the standard model: ``HR_rest + u * (HRmax - HR_rest)`` with ``u``
its demand as a fraction of the person's reserve, fast and slow components together; every model
leaves the slow cardiac drift out, so a zone reached only by drifting up does not count). The zone
is the one the coach set for this session.

What a policy can hold through the conditioning decides which settings count:

* ``static``: none to change: the routine's conditioning at the starting step;
* ladder policies (``threshold``, ``fuzzy``): any step, with the routine's activities as they
  come; their demands are averaged over the conditioning (weighted by duration), since the
  one-minute lag of the heart smooths the alternation (their settled heart rates are averaged);
* policies that pick activities (``predictive``): any activity with a stated cost, held, at
  any step.

Reachable: some setting settles inside the zone. Otherwise the person is ``below`` (every
setting settles below it), ``above`` (every one above) or in a ``gap`` (the settings jump
over the zone).
"""

from __future__ import annotations

from dataclasses import dataclass

from hri_physio_coach.media_names import tempo_from_name
from hri_physio_coach.participant.perception import KNOWN_ACTIVITIES
from hri_physio_coach.participant.physiology import Activity, ParticipantParams
from hri_physio_coach.routine import Routine

REACHABLE, BELOW, ABOVE, GAP = "reachable", "below", "above", "gap"


@dataclass(frozen=True)
class Reach:
    verdict: str  # reachable | below | above | gap
    lowest: float  # bpm: the lowest and highest settled heart rate of the policy's settings
    highest: float

    @property
    def reachable(self) -> bool:
        return self.verdict == REACHABLE




def reach(p: ParticipantParams, low: float, high: float, routine: Routine, phase: str,
          speeds: tuple[float, ...], suffixes: tuple[str, ...], start_index: int, *,
          adapts: bool, chooses_activity: bool) -> Reach:
    """The verdict for one person, zone ``[low, high]`` and a policy's controls in ``phase``."""
    tempos = [tempo_from_name(s) or 120.0 for s in suffixes]
    steps = range(len(speeds)) if adapts or chooses_activity else [start_index]
    slots = routine.phase(phase).activities

    def hr_of(gesture: str, k: int) -> float:  # what the participant does with an unknown gesture: rest
        name = gesture if gesture in KNOWN_ACTIVITIES else "rest"
        return p.settled_hr(Activity(name, tempos[k], speeds[k]))

    if chooses_activity:
        gestures = {str(a.attrs.get("gesture", a.name)) for a in routine.choices(phase)}
        hrs = [hr_of(g, k) for g in sorted(gestures) for k in steps]
    else:
        total = sum(a.duration for a in slots)
        hrs = [sum(a.duration * hr_of(str(a.attrs.get("gesture", a.name)), k) for a in slots) / total
               for k in steps]
    lowest, highest = min(hrs), max(hrs)
    if any(low <= h <= high for h in hrs):
        verdict = REACHABLE
    elif highest < low:
        verdict = BELOW
    elif lowest > high:
        verdict = ABOVE
    else:
        verdict = GAP
    return Reach(verdict, lowest, highest)
