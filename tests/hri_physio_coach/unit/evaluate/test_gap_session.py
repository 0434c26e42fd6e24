"""A whole session of a person in a gap (marching settles below the zone, stepping above): the adaptive
policy alternates the two, says so in a zone_gap event, and keeps heart rate in the zone."""

from __future__ import annotations

from hri_physio_coach.evaluate.metrics import session_metrics
from hri_physio_coach.evaluate.simulation import SessionSpec, simulate_session
from hri_physio_coach.participant.physiology import ParticipantParams

# Unfit: stepping even at the slowest step settles above HRR70, marching even at the fastest below HRR40.
GAP_PERSON = ParticipantParams(vo2max=24.0, marching_mets=3.0, tempo_compliance=0.3)


def test_a_gap_is_bridged_by_alternating_and_announced() -> None:
    runs = {policy: simulate_session(SessionSpec(policy, 0, GAP_PERSON, 3, 3))
            for policy in ("adaptive", "threshold")}
    adaptive = runs["adaptive"]
    gaps = adaptive.of("zone_gap")
    assert len(gaps) == 1 and "alternating" in gaps[0]["reason"]
    row = session_metrics(adaptive)
    assert row["in_zone"] >= 0.85
    assert row["in_zone"] > session_metrics(runs["threshold"])["in_zone"] + 0.2
    assert row["above_hrr70_s"] <= 30
    # Both activities run in the conditioning: the alternation, not one setting parked below.
    levels = {e["level"] for e in adaptive.of("activity_choice") if e["t"] > gaps[0]["t"]}
    assert len(levels) >= 2
