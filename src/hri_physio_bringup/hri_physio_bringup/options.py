"""``hri_physio_session``'s options, declared once (no rclpy: checked before anything starts).

The launcher is not a ROS node, so these are not ROS parameters: they are the launcher's flags
(``add_config_arguments``) and the values it turns into the nodes' own configurations
(:mod:`hri_physio_bringup.plan`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

from pydantic import field_validator, model_validator

from hri_physio_bridge.config import NodeConfig, option
from hri_physio_bringup.live import DEFAULT_LIVE, parse_live
from hri_physio_coach.config import PolicyName
from hri_physio_coach.participant.models import MODEL_NAMES

PROG = "hri_physio_session"
#: ``--source`` values: the simulated participant, a real strap, or a capture of one replayed.
SIMULATED, POLAR, POLAR_REPLAY = "simulated", "polar:", "polar-replay:"


class SessionConfig(NodeConfig):
    """The closed loop with a simulated participant (or a Polar strap): pace, participant, inputs, where
    it all goes."""

    speed: float = option(30.0, "sim seconds per wall second (30: the 23-min routine in about 46 s; "
                          "1 = real time)", gt=0, le=1000)
    policy: PolicyName | None = option(None, "adaptation policy (none given: the coach configuration's, "
                                       "threshold in the packaged coach.yaml)")
    age: float = option(33.0, "the simulated participant's age, also the coach's part_age", unit="years",
                        gt=0, le=120)
    participant_seed: int = option(1, "seed of the simulated participant's variability", ge=0)
    participant_model: str = option("standard", f"the simulated participant's heart: a participant model "
                                    f"({', '.join(MODEL_NAMES)}; docs/PARTICIPANT_MODEL.md), as "
                                    f"hri_physio_evaluate --model")
    hr_source: Literal["strap", "ecg"] = option("strap", "the coach's heart rate: the strap's HR or the "
                                                "processor's HR from ECG")
    conf: str = option("", "the coach's YAML file ('' = the packaged coach.yaml)")
    routine: str = option("", "routine YAML file ('' = the coach configuration's, else the packaged "
                          "exercise routine)")
    out: str = option("sessions", "parent folder of the session folders (<participant>_<date-time>/)")
    no_record: bool = option(False, "do not record a bag", switch=True)
    no_ecg: bool = option(False, "do not stream ECG into ROS 2 nor process it", switch=True)
    device_id: str = option("", "simulated Polar device id in the LSL stream names ('' = SIM + a "
                            "per-session suffix, so two sessions never resolve each other's streams)")
    log_data: bool = option(False, "the receivers also write every sample to CSV (the folder's csv/)",
                            switch=True)
    startup_timeout: float = option(180.0, "wall time to wait for the nodes and the first heart rate (a "
                                    "dozen processes start in 10-20 s on an idle 2-core machine, minutes "
                                    "on a busy one)", unit="s", gt=0)
    progress_every: float = option(60.0, "session time between progress lines when the output is not a "
                                   "terminal", unit="s", gt=0)
    verbose: bool = option(False, "every node's output on the console, interleaved (it always goes to "
                           "the folder's logs/)", switch=True)
    max_restarts: int = option(3, "restarts of one restartable node (robot side, streamers, receivers, "
                               "processor) after it died, each after a backoff (0.5 s doubling to 8 s); one "
                               "more death ends the session (0: any node's death ends it). The coach, the "
                               "recorder and the strap are never restarted: their loss ends the session",
                               ge=0, le=100)
    no_report: bool = option(False, "do not write the report at the end (hri_physio_report can later)",
                             switch=True)
    source: str = option(SIMULATED, "where heart rate comes from: simulated (the simulated participant), "
                         "polar:<device id> (a real Polar H10 through polar_streamer; real time only), "
                         "polar-replay:<capture file> (a polar_streamer capture replayed as if the strap "
                         "were there: tests, demos)")
    audio_sink: Literal["null", "device", "auto"] = option(
        "null", "the audio streamer's output: null (no sound, the music still plays on the session's "
        "clock), device (the sound card, or a start-up error), auto (the sound card when one exists)")
    lab: str = option("", "lab file (YAML) naming the lab's hosts and their roles, for a session "
                      "across computers ('' = everything on this host, discovery kept to it; see "
                      "docs/ARCHITECTURE.md, running a lab)")
    role: Literal["", "sensor", "robot", "station"] = option(
        "", "this host's part of a lab session (with --lab): sensor (the strap side, on LSL), robot "
        "(qt_controller, the mock robot, the media streamers) or station (receivers, processor, coach, "
        "recorder and the session's clock)")

    live: str = option("", f"serve the session live to Foxglove (WebSocket protocol) on [HOST:]PORT from "
                       f"this host (the station): heart rate, zone, phase, activity, adaptations, robot "
                       f"actions, media status, video preview; '--live' alone = {DEFAULT_LIVE}, this host "
                       f"only; a HOST such as 0.0.0.0 opens it to the network ('' = off). Open it in "
                       f"Foxglove with src/hri_physio_bringup/config/foxglove_layout.json")

    @field_validator("live")
    @classmethod
    def _live(cls, value: str) -> str:
        if value:
            parse_live(value)
        return value

    @property
    def live_address(self) -> tuple[str, int] | None:
        """Where the live view serves (host, port), None when it is off."""
        return parse_live(self.live) if self.live else None

    @model_validator(mode="before")
    @classmethod
    def _real_time_for_a_strap(cls, data: Any) -> Any:
        """A strap beats in real time: --source polar... without --speed runs at 1x."""
        if isinstance(data, dict) and str(data.get("source", "")).startswith((POLAR, POLAR_REPLAY)):
            return {"speed": 1.0, **data}
        return data

    @property
    def polar(self) -> bool:
        """Heart rate from a Polar strap (or its replay), not from the simulated participant."""
        return self.source != SIMULATED

    @property
    def polar_device(self) -> str:
        """The strap's id after ``polar:`` ('' for the other sources)."""
        return self.source.removeprefix(POLAR) if self.source.startswith(POLAR) else ""

    @property
    def polar_replay(self) -> str:
        """The capture file after ``polar-replay:`` ('' for the other sources)."""
        return self.source.removeprefix(POLAR_REPLAY) if self.source.startswith(POLAR_REPLAY) else ""

    @model_validator(mode="after")
    def _consistent(self) -> SessionConfig:
        for name in ("conf", "routine"):
            path = getattr(self, name)
            if path and not Path(path).is_file():
                raise ValueError(f"{name}: {path} does not exist")
        if self.hr_source == "ecg" and self.no_ecg:
            raise ValueError("hr_source ecg needs the ECG path: drop --no-ecg")
        if self.participant_model not in MODEL_NAMES:
            raise ValueError(f"participant_model: unknown participant model {self.participant_model!r}; "
                             f"choose from {', '.join(MODEL_NAMES)}")
        if self.device_id and not self.device_id.replace("-", "").replace("_", "").isalnum():
            raise ValueError(f"device_id may hold letters, digits, '-' and '_' only, got {self.device_id!r}")
        self._check_source()
        if bool(self.lab) != bool(self.role):
            raise ValueError("a lab session needs both --lab <lab file> and --role sensor|robot|station"
                             if self.role else "--lab needs --role sensor|robot|station (this host's part)")
        if self.lab and not Path(self.lab).is_file():
            raise ValueError(f"lab: {self.lab} does not exist")
        return self

    def _check_source(self) -> None:
        if self.source == SIMULATED:
            return
        if not self.source.startswith((POLAR, POLAR_REPLAY)):
            raise ValueError(f"source must be simulated, polar:<device id> or polar-replay:<capture file>, "
                             f"got {self.source!r}")
        if self.speed != 1.0:
            raise ValueError(f"source {self.source}: a strap runs in real time, --speed must be 1 "
                             f"(got {self.speed:g})")
        if self.device_id:
            raise ValueError("device_id names the simulated strap: with a Polar source the id is "
                             "polar:<device id>")
        if self.participant_model != "standard":
            raise ValueError(f"participant_model {self.participant_model} is the simulated participant's: "
                             f"with source {self.source} the heart is the strap wearer's")
        if self.source.startswith(POLAR):
            if not re.fullmatch(r"[0-9A-Fa-f]{8}", self.polar_device):
                raise ValueError(f"source polar:<device id>: give the strap's 8-hex-digit id (printed on it, "
                                 f"listed by polar_streamer --scan), got {self.source!r}")
        elif not Path(self.polar_replay).is_file():
            raise ValueError(f"source {self.source}: capture file {self.polar_replay} does not exist")
