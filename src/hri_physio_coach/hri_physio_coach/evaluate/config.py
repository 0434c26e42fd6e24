"""hri_physio_evaluate's options, declared once (flags, ``--conf`` YAML keys, help and checks)."""

from __future__ import annotations

from pydantic import model_validator

from hri_physio_bridge.config import NodeConfig, option
from hri_physio_coach.participant.models import MODEL_NAMES
from hri_physio_coach.policies.registry import POLICY_NAMES

DEFAULT_POLICIES = ["static", "threshold", "fuzzy", "predictive", "adaptive"]


class EvaluateConfig(NodeConfig):
    """Which people, which policies, where the results go and how the work is spread."""

    cohort: int = option(200, "people in the simulated cohort", ge=1)
    seed: int = option(1, "seed of the cohort and of every random draw of its sessions (paired across "
                       "policies)", ge=0)
    policies: list[str] = option(DEFAULT_POLICIES, "policies to compare, comma-separated "
                                 f"({', '.join(POLICY_NAMES)})", min_length=1)
    out: str = option("evaluation", "output directory (created if needed; its result files are replaced)",
                      min_length=1)
    jobs: int = option(0, "worker processes on this machine (0: one per core)", ge=0)
    scheduler: str = option("", "address of a running Dask distributed scheduler (e.g. tcp://host:8786) "
                            "to run the sessions on instead of local processes")
    model: str = option("standard", "participant model the cohort is drawn from and simulated with "
                        f"({', '.join(MODEL_NAMES)}; docs/PARTICIPANT_MODEL.md)")
    population: str = option("", "CSV file of participants, one per row, columns named as the model's "
                             "parameters (age, hr_rest, vo2max, ...); empty: sample the cohort")
    age_min: float = option(20.0, "youngest age of the sampled cohort", unit="years", gt=0, le=120)
    age_max: float = option(50.0, "oldest age of the sampled cohort", unit="years", gt=0, le=120)
    coach_conf: str = option("", "coach YAML file the sessions run with (as qt_physio_coach --conf); "
                             "empty: the packaged defaults")
    hr_latency: float = option(0.1, "delay of each heart-rate sample from the strap to the coach", unit="s",
                               ge=0, le=5)
    sensitivity: bool = option(False, "also move each assumed model parameter to both ends of its range "
                               "(the sensitivity table)", switch=True)
    sensitivity_cohort: int = option(100, "people per variant of the sensitivity sweep (the first of the "
                                     "cohort)", ge=1)
    sensitivity_policies: list[str] = option([], "policies of the sensitivity sweep, comma-separated (empty: "
                                             "the same as policies; the winner is always in it)")
    traces: int = option(3, "people whose heart-rate traces are plotted under every policy", ge=0)
    bootstrap: int = option(2000, "bootstrap resamples for the CI of the median", ge=100)
    progress: bool = option(True, "show a progress bar on stderr")

    @model_validator(mode="after")
    def _check(self) -> EvaluateConfig:
        unknown = [p for p in [*self.policies, *self.sensitivity_policies] if p not in POLICY_NAMES]
        if unknown:
            raise ValueError(f"policies: unknown policy {', '.join(map(repr, unknown))}; choose from "
                             f"{', '.join(POLICY_NAMES)}")
        if self.model not in MODEL_NAMES:
            raise ValueError(f"model: unknown participant model {self.model!r}; choose from "
                             f"{', '.join(MODEL_NAMES)}")
        if len(set(self.policies)) != len(self.policies):
            raise ValueError(f"policies: each policy once, got {','.join(self.policies)}")
        if not self.age_min < self.age_max:
            raise ValueError(f"need age_min < age_max, got {self.age_min:g}, {self.age_max:g}")
        return self
