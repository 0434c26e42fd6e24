"""The simulated cohort: who takes part, their seeds, and the model variants of the sensitivity table.

People come from the participant model's sampler (``--model``, :mod:`~hri_physio_coach.participant.models`;
the standard one is :func:`~hri_physio_coach.participant.physiology.sample_population`), seeded,
or from a population file (CSV, one person per row, columns named as the fields of
:class:`~hri_physio_coach.participant.physiology.ParticipantParams`; missing columns keep
their defaults). Each person gets two seeds derived from ``--seed`` (numpy ``SeedSequence``
spawned per person): one for their heart's noise and one for the coach's draws, the same
under every policy, so policies are compared on the same people with the same luck.
"""

from __future__ import annotations

import csv
import dataclasses
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hri_physio_coach.participant.models import model_info
from hri_physio_coach.participant.physiology import ParticipantParams


class PopulationError(ValueError):
    """A population file that cannot be used; the message names the file, row and column."""


@dataclass(frozen=True)
class Assumption:
    """A model parameter without a single published value, and the ends of its plausible range."""

    name: str
    low: float
    high: float
    why: str


#: The model's assumed parameters, each moved to both ends of its range for the sensitivity table.
ASSUMPTIONS = (
    Assumption("tempo_compliance", 0.3, 1.0, "share of a tempo change the stepping follows (0.3-1)"),
    Assumption("gesture_gain", 0.0, 0.5, "effort per unit of the robot's gesture speed (assumed 0-0.5)"),
    Assumption("tau_on", 20.0, 120.0, "slow time constant while HR rises (60 +/- 20 s, clipped 20-120)"),
    Assumption("tau_off", 25.0, 140.0, "slow time constant while HR falls (75 +/- 20 s, clipped 25-140)"),
    Assumption("tau_fast", 5.0, 20.0, "fast (neural) time constant (about 10 s)"),
    Assumption("dead_time", 4.0, 15.0, "dead time of the slow component (about 8 s)"),
    Assumption("marching_mets", 3.0, 4.5, "cost of marching in place at 120 BPM (assumed 3.5 METs)"),
    Assumption("drift_amplitude", 0.03, 0.12, "cardiac drift amplitude (0.03-0.12 of HRR)"),
    Assumption("calibration_offset", 0.0, 6.0, "seated anticipation during calibration (3 +/- 3 bpm)"),
    Assumption("lateral_cost", 0.85, 1.15, "lateral knee lifts' cost / step-ups' (one label, 1 +/- 0.1)"),
)


def participant_seeds(seed: int, n: int) -> list[tuple[int, int]]:
    """(heart noise seed, coach seed) per person, derived from ``seed``."""
    children = np.random.SeedSequence(seed).spawn(n)
    return [tuple(int(x) for x in child.generate_state(2)) for child in children]  # type: ignore[misc]


def _fields(cls: type[ParticipantParams]) -> dict[str, dataclasses.Field]:  # type: ignore[type-arg]
    return {f.name: f for f in dataclasses.fields(cls)}


def _value(name: str, text: str, where: str,
           cls: type[ParticipantParams] = ParticipantParams) -> float | bool:
    kind = _fields(cls)[name].type
    if kind == "bool":
        lowered = text.strip().lower()
        if lowered in ("true", "1", "yes"):
            return True
        if lowered in ("false", "0", "no"):
            return False
        raise PopulationError(f"{where}: {name} must be true or false, got {text!r}")
    try:
        return float(text)
    except ValueError:
        raise PopulationError(f"{where}: {name} must be a number, got {text!r}") from None


def load_population(path: str | Path, model: str = "standard") -> list[ParticipantParams]:
    """People of ``model`` from a CSV file (one per row); :class:`PopulationError` on anything unusable."""
    cls = model_info(model).params
    fields = _fields(cls)
    p = Path(path)
    if not p.is_file():
        raise PopulationError(f"population file {p} does not exist")
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
            columns = list(rows[0]) if rows else []
    except (UnicodeDecodeError, csv.Error) as exc:
        raise PopulationError(f"population file {p} is not a readable CSV file: {exc}") from None
    if not rows:
        raise PopulationError(f"population file {p} has no rows (a header line, then one person per line)")
    unknown = sorted(set(columns) - set(fields))
    if unknown:
        separators = ((";", "semicolons"), ("\t", "tabs"))
        separator = next((name for sep, name in separators if sep in columns[0]), None)
        hint = f" (its header is split by {separator}: columns are separated by commas)" if separator else ""
        raise PopulationError(f"population file {p}: unknown column(s) {', '.join(unknown)}{hint}; "
                              f"known: {', '.join(fields)}")
    people = []
    for i, row in enumerate(rows, start=2):
        where = f"population file {p}, line {i}"
        if None in row or any(v is None or not v.strip() for v in row.values()):
            raise PopulationError(f"{where}: every column needs a value")
        person = cls(**{k: _value(k, v, where, cls) for k, v in row.items()})  # type: ignore[arg-type]
        try:
            person.validate()
        except ValueError as exc:
            raise PopulationError(f"{where}: {exc}") from None
        people.append(person)
    return people


def make_cohort(n: int, seed: int, age_range: tuple[float, float] = (20.0, 50.0),
                population: str | Path | None = None, model: str = "standard") -> list[ParticipantParams]:
    """``n`` people of participant model ``model``: sampled with ``seed``, or the first ``n`` of a file."""
    if population:
        people = load_population(population, model)
        if len(people) < n:
            raise PopulationError(f"population file {population} has {len(people)} people, fewer than "
                                  f"the cohort of {n}")
        return people[:n]
    return model_info(model).sample(n, seed, age_range)


def variants(people: list[ParticipantParams], assumptions: tuple[Assumption, ...] = ASSUMPTIONS
             ) -> list[tuple[str, list[ParticipantParams]]]:
    """The cohort with one assumed parameter set to one end of its range for everyone (only the
    parameters the cohort's participant model uses)."""
    out = []
    known = {f.name for f in dataclasses.fields(people[0])} if people else set()
    uses = model_info(people[0].model).uses if people else None
    for a in assumptions:
        if a.name not in known or (uses is not None and a.name not in uses):
            continue  # a parameter this participant model does not have or does not use
        for value in (a.low, a.high):
            out.append((f"{a.name}={value:g}", [replace(p, **{a.name: value}) for p in people]))
    return out
