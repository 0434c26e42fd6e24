"""``simulated_participant``'s options, declared once (no rclpy, no pylsl: checkable before launch).

The model parameters are those of :class:`~hri_physio_coach.participant.physiology.ParticipantParams`
(defaults taken from it, docs/PARTICIPANT_MODEL.md explains them); the model's own cross-checks
(``hr_rest < hr_max_true``, ...) run in the validator, so a bad value is one
:class:`~hri_physio_bridge.config.ConfigError` line naming the option.
"""

from __future__ import annotations

import dataclasses

from pydantic import model_validator

from hri_physio_bridge import topics
from hri_physio_bridge.config import NodeConfig, option
from hri_physio_coach.participant.models import MODEL_NAMES, as_model
from hri_physio_coach.participant.physiology import REST_VO2, ParticipantParams

#: The node's name: the section of a ROS params file that holds its options.
PARTICIPANT_NODE = "simulated_participant"
_P = ParticipantParams()


class ParticipantNodeConfig(NodeConfig):
    """The simulated person (model parameters) and the simulated strap (LSL streams)."""

    # --- the person (ParticipantParams) --------------------------------------------------------
    model: str = option("standard", f"participant model ({', '.join(MODEL_NAMES)}; "
                        "docs/PARTICIPANT_MODEL.md): "
                        "the options below are its shared parameters, the model's own keep their defaults")
    age: float = option(_P.age, "age", unit="years", gt=0, le=120)
    female: bool = option(_P.female, "sex for the population model")
    hr_rest: float = option(_P.hr_rest, "resting heart rate", unit="bpm", ge=30)
    hr_max_true: float = option(_P.hr_max_true, "true maximal heart rate", unit="bpm", gt=0)
    vo2max: float = option(_P.vo2max, "maximal oxygen uptake", unit="ml/kg/min", gt=REST_VO2)
    step_height: float = option(_P.step_height, "step height H of the stepping equation", unit="m", gt=0)
    tempo_compliance: float = option(_P.tempo_compliance, "how far the cadence follows the music tempo "
                                     "(rho)", ge=0, le=1)
    gesture_gain: float = option(_P.gesture_gain, "effort gain per unit of gesture speed (gamma)", ge=0)
    marching_mets: float = option(_P.marching_mets, "cost of marching at 120 BPM", unit="METs", gt=0)
    arm_work: float = option(_P.arm_work, "extra effort with both arms forward (fraction)", ge=0)
    tau_fast: float = option(_P.tau_fast, "time constant of the fast (neural) HR component", unit="s", gt=0)
    tau_on: float = option(_P.tau_on, "time constant of the slow component, rising", unit="s", gt=0)
    tau_off: float = option(_P.tau_off, "time constant of the slow component, falling", unit="s", gt=0)
    dead_time: float = option(_P.dead_time, "dead time of the slow component", unit="s", ge=0)
    drift_amplitude: float = option(_P.drift_amplitude, "cardiac drift A_d (fraction of HRR)", ge=0)
    tau_drift: float = option(_P.tau_drift, "time constant of the cardiac drift", unit="s", gt=0)
    calibration_offset: float = option(_P.calibration_offset, "seated anticipation added to HR", unit="bpm")
    sdnn_rest: float = option(_P.sdnn_rest, "SD of RR intervals at rest", unit="s", ge=0)
    artefact_rate: float = option(_P.artefact_rate, "missed or extra beats in the reported RR (fraction)",
                                  ge=0, le=1)
    strap_jitter: float = option(_P.strap_jitter, "SD of the jitter on the strap's 1-Hz heart rate",
                                 unit="bpm",
                                 ge=0)
    dropout_rate: float = option(_P.dropout_rate, "strap dropouts (bursts of 1-5 s with no heart rate): "
                                 "a burst starts in a reporting second with chance rate/3, so "
                                 "rate/(1+2rate/3) of seconds are lost (about rate when small)", ge=0, lt=1)
    reaction_period: float = option(_P.reaction_period, "a new instruction is taken up at the next multiple "
                                    "of this period from the coach's session start (0: at once)", unit="s",
                                    ge=0)
    # --- the node and the simulated strap ------------------------------------------------------
    seed: int = option(0, "seed of the participant's variability", ge=0)
    device_id: str = option("SIM0001", "Polar device id in the LSL stream names PolarH10/<id>/<ECG|HR|RR>",
                            min_length=1)
    name_prefix: str = option("", "prefix of the LSL stream names (<prefix>/PolarH10/...)")
    ecg_rate: float = option(130.0, "ECG sampling rate", unit="Hz", gt=0)
    update_period: float = option(0.1, "model step on ROS time (under sim time keep each /clock step <= it)",
                                  unit="s", gt=0)
    command_topic: str = option(topics.QT_COMMANDS, "robot command lines the participant follows",
                                min_length=1)
    state_topic: str = option(topics.PARTICIPANT_STATE, "the model's true state (JSON, 1 Hz)", min_length=1)
    heard_topic: str = option(topics.PARTICIPANT_HEARD, "a confirmation (JSON) of each command and audio "
                              "status taken in: the session launcher holds sim time for it", min_length=1)
    session_events_topic: str = option(topics.COACH_EVENTS, "the coach's events: its 'session_start' starts "
                                       "the seeded session model (until then the person rests on another "
                                       "random stream)", min_length=1)
    audio_status_topic: str = option(topics.AUDIO_STATUS, "the audio streamer's status (JSON): the tempo "
                                     "it reports as playing is the one the participant follows (without "
                                     "it, the tempo named in 'set audio' commands)", min_length=1)

    @model_validator(mode="after")
    def _model_checks(self) -> ParticipantNodeConfig:
        if self.model not in MODEL_NAMES:
            raise ValueError(f"model: unknown participant model {self.model!r}; choose from "
                             f"{', '.join(MODEL_NAMES)}")
        self.params.validate()  # ValueError: reported as a configuration error
        return self

    @property
    def params(self) -> ParticipantParams:
        names = {f.name for f in dataclasses.fields(ParticipantParams)}
        shared = ParticipantParams(**{k: v for k, v in self.as_dict().items() if k in names})
        return as_model(shared, self.model)

    def lsl_name(self, kind: str) -> str:
        """The LSL stream name of ``kind`` (ECG, HR or RR)."""
        prefix = f"{self.name_prefix.rstrip('/')}/" if self.name_prefix else ""
        return f"{prefix}PolarH10/{self.device_id}/{kind}"
