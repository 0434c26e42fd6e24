"""Configuration of the NeuroKit2 processor: one declaration drives flags, YAML, ROS parameters, help.

The seed's neurokitProcessor.py read ``name``, ``input``, ``buffer`` (samples per
processing window), ``window`` (samples kept for the next window, i.e. the overlap),
``plot`` and ``verbose``. Those keys are accepted and translated (:meth:`translate_keys`);
ours are in seconds.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal

from pydantic import TypeAdapter, ValidationError, model_validator

from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError, NodeConfig, option
from hri_physio_bridge.streamers.factory import split_uri
from hri_physio_processing.features import FeatureSettings

#: Per-mode defaults for options left at 0 ("auto").
MODE_DEFAULTS: dict[str, dict[str, float]] = {
    "ecg": {"flatline_seconds": 2.0, "saturation_fraction": 0.01, "dedup_seconds": 0.2},
    # Optical sensors clip systolic peaks and troughs routinely without losing the beats' timing; a
    # clipped stretch that hides beats is caught as a beat-free stretch (max_beat_gap_seconds).
    "ppg": {"flatline_seconds": 2.0, "saturation_fraction": 0.05, "dedup_seconds": 0.2},
    # Skin conductance can sit still for seconds and plateau at its peaks.
    "eda": {"flatline_seconds": 10.0, "saturation_fraction": 0.05, "dedup_seconds": 1.0},
}

DEFAULT_RATE = 130.0


class ProcessorConfig(NodeConfig):
    """Every option of neurokit_processor, with a default that runs without hardware."""

    SEED_KEYS: ClassVar[tuple[str, ...]] = ("name", "input", "buffer", "window", "plot", "verbose")

    input: str = option(f"ros:{topics.POLAR_H10_ECG}", "source: ros:/<topic>, lsl:<name>[?type=&source_id=], "
                        "csv:<file>[?rate=] (no scheme = LSL name, as the seed)", min_length=1)
    output_prefix: str = option("", "absolute topic prefix of the outputs, e.g. /physio/polar_h10/ecg "
                                "('' = the input topic; required for lsl: and csv: inputs)")
    mode: Literal["ecg", "ppg", "eda"] = option("ecg", "signal kind")
    sampling_rate: float = option(DEFAULT_RATE, "nominal rate of the input (checked against the "
                                  "timestamps)", unit="Hz", gt=0)
    num_channels: int = option(1, "channels per input sample (ROS 2 input frames must match)", ge=1)
    channel: int = option(0, "which input channel to process (0-based)", ge=0)
    window_seconds: float = option(60.0, "signal per processed window", unit="s", gt=0)
    hop_seconds: float = option(5.0, "time between window starts (window - hop = overlap)", unit="s", gt=0)
    hrv_window_seconds: float = option(300.0, "LF, HF and LF/HF from the beats of this much clean signal "
                                       "before each window's published end (5 min for LF/HF, 2 min LF, "
                                       "1 min HF; 0 = on each window itself)", unit="s", ge=0)
    input_depth: int = option(4000, "frames a ros: input subscription holds until the node takes them "
                              "(keep below Fast DDS's 5000-sample reader limit, else a publisher that "
                              "outruns the processor is blocked; frames lost are counted and reported)",
                              unit="frames", ge=1)
    lsl_output: bool = option(False, "also publish every output on LSL")
    lsl_prefix: str = option("", "LSL stream-name prefix ('' = output_prefix)")
    quality_method: Literal["templatematch", "averageQRS", "zhao2018", "none"] = option(
        "templatematch", "NeuroKit2 signal quality method (ECG)")
    min_quality: float = option(0.5, "windows with a lower quality are flagged (features NaN)", ge=0, le=1)
    min_beats: int = option(5, "fewer beats in a window: features NaN (a rate needs two)", ge=2)
    min_hr: float = option(30.0, "mean rate below this: flagged, not a heart signal", unit="bpm", ge=0)
    max_hr: float = option(220.0, "mean rate above this: flagged", unit="bpm", gt=0)
    flatline_seconds: float = option(0.0, "a constant stretch this long flags the window (0 = mode "
                                     "default: 2 s ECG/PPG, 10 s EDA)", unit="s", ge=0)
    saturation_fraction: float = option(0.0, "this share of samples at the extremes flags the window "
                                        "(0 = mode default: 1 percent ECG, 5 percent PPG and EDA)",
                                        ge=0, le=1)
    rate_tolerance: float = option(0.05, "relative mismatch between timestamps and sampling_rate that "
                                   "flags a window", gt=0, lt=1)
    gap_factor: float = option(1.5, "timestamp step (in sample periods) that counts as a gap and restarts "
                               "windows", gt=1)
    min_window_seconds: float = option(10.0, "shortest stretch between gaps (or at the end) still "
                                       "processed", unit="s", ge=0)
    edge_guard_seconds: float = option(2.0, "overlapping windows publish peaks up to this far from their "
                                       "end", unit="s", ge=0)
    dedup_seconds: float = option(0.0, "peaks closer than this to the last published one are duplicates "
                                  "(0 = mode default: 0.2 s ECG/PPG, 1 s EDA)", unit="s", ge=0)
    polarity: Literal["auto", "upright", "inverted"] = option(
        "auto", "which way up the signal is: auto turns an ECG window over when its R waves point down "
        "(strap upside down, electrodes swapped) and takes PPG as it comes; inverted turns every ECG "
        "or PPG window over (a Polar OH1 / Verity Sense sends its raw PPG upside down); upright "
        "never (EDA is always taken as it comes)")
    correct_artifacts: bool = option(False, "let NeuroKit2 correct R-peak artefacts "
                                     "(ecg_peaks correct_artifacts)")
    max_beat_gap_seconds: float = option(2.0, "an interval between beats longer than this is a beat-free "
                                         "stretch (saturation, flat line, baseline jump): left out of the "
                                         "rate, and the window's HRV is NaN", unit="s", gt=0)
    max_corrected_fraction: float = option(0.1, "more beats than this share corrected as artefacts "
                                           "(missed, extra, ectopic; Lipponen & Tarvainen 2019): HRV NaN",
                                           ge=0, le=1)
    min_regular_fraction: float = option(0.8, "PPG: fewer clean inter-beat intervals than this share "
                                         "within 20 percent of their median: rate and HRV NaN (noise or "
                                         "irregular rhythm; 0 = never)", ge=0, le=1)
    hrv_spectrum: Literal["welch", "lomb"] = option("welch", "LF, HF by Welch's method on the NN series "
                                                     "resampled at 4 Hz (cubic), or by the Lomb-Scargle "
                                                     "periodogram of the NN intervals at their beat times")
    resolve_timeout: float = option(10.0, "how long one attempt waits for an LSL input to appear; "
                                    "attempts repeat (with backoff) until it does", unit="s", ge=0)
    drain_timeout: float = option(5.0, "at a stop, the most time spent processing the frames already "
                                  "received, plus drain_per_frame for each (what is left is an error)",
                                  unit="s", ge=0)
    drain_per_frame: float = option(0.02, "the time a stop allows per frame already received", unit="s", ge=0)
    wait_for_consumers: float = option(0.0, "how long to wait for a listener on every ROS output before "
                                       "reading the input (topics are volatile: a log replay would "
                                       "otherwise lose its first windows; 0 = no wait)", unit="s", ge=0)
    verbose: bool = option(False, "log every window")

    # -- the seed's keys -----------------------------------------------------------------------
    @classmethod
    def translate_keys(cls, data: dict[str, Any], source: str) -> dict[str, Any]:
        """Map the seed's keys (samples) onto ours (seconds); refuse contradictory combinations."""
        out = dict(data)
        if "buffer" in out:
            if "window_seconds" in out:
                raise ConfigError(
                    f"{source}: give either buffer (samples, the seed's key) or window_seconds, not both")
            if "hop_seconds" in out:
                raise ConfigError(f"{source}: give either buffer/window (samples) or hop_seconds, not both")
            rate = _number(out.get("sampling_rate", DEFAULT_RATE), "sampling_rate", source)
            buffer = _number(out.pop("buffer"), "buffer", source)
            keep = _number(out.pop("window", 0), "window", source)
            if not 0 <= keep < buffer:
                raise ConfigError(
                    f"{source}: window (samples kept, {keep}) must be >= 0 and below buffer ({buffer})")
            if rate > 0:
                out["window_seconds"] = buffer / rate
                out["hop_seconds"] = (buffer - keep) / rate
        elif "window" in out:
            raise ConfigError(f"{source}: window (the seed's overlap in samples) needs buffer too")
        if out.pop("plot", False) not in (False, "false", "False", 0):
            raise ConfigError(f"{source}: plot is not supported (the node runs headless); record and plot "
                              "offline")
        name = out.pop("name", None)
        if name is not None and "lsl_prefix" not in out:
            out["lsl_prefix"] = "/" + str(name).strip("/")
        inp = out.get("input")
        if isinstance(inp, str) and inp and ":" not in inp:
            out["input"] = "lsl:" + inp  # the seed's input was an LSL stream name
        return out

    # -- cross-field rules ---------------------------------------------------------------------
    @model_validator(mode="after")
    def _consistent(self) -> ProcessorConfig:
        try:
            scheme, address = split_uri(self.input)
        except ValueError as exc:
            raise ValueError(f"input: {exc}") from None
        if scheme == "ros" and not address.startswith("/"):
            raise ValueError(f"input: ROS topic {address!r} must be absolute (start with '/'), "
                             f"e.g. ros:/{address.lstrip('~/')}")
        if self.output_prefix and not self.output_prefix.startswith("/"):
            raise ValueError(f"output_prefix must be an absolute ROS name (start with '/'), "
                             f"got {self.output_prefix!r}")
        if scheme != "ros" and not self.output_prefix:
            raise ValueError(f"output_prefix is required when the input is not a ROS topic (input is "
                             f"{self.input!r}); e.g. output_prefix: /physio/polar_h10/{self.mode}")
        if self.channel >= self.num_channels:
            raise ValueError(f"channel must index one of the {self.num_channels} channel(s), "
                             f"got {self.channel}")
        if self.window_samples < 2:
            raise ValueError(f"window_seconds must cover at least 2 samples, got {self.window_seconds} s")
        if not 1 <= self.hop_samples <= self.window_samples:
            raise ValueError(f"hop_seconds must cover at least one sample and at most window_seconds "
                             f"({self.window_seconds} s), got {self.hop_seconds} s")
        if self.min_hr >= self.max_hr:
            raise ValueError(f"min_hr must be below max_hr, got {self.min_hr} and {self.max_hr}")
        if self.min_window_seconds > self.window_seconds:
            raise ValueError(f"min_window_seconds ({self.min_window_seconds} s) cannot exceed "
                             f"window_seconds ({self.window_seconds} s)")
        return self

    # -- derived values ------------------------------------------------------------------------
    @property
    def window_samples(self) -> int:
        return round(self.window_seconds * self.sampling_rate)

    @property
    def hop_samples(self) -> int:
        return round(self.hop_seconds * self.sampling_rate)

    @property
    def input_scheme(self) -> str:
        return split_uri(self.input)[0]

    def mode_default(self, key: str) -> float:
        value = float(getattr(self, key))
        return value if value > 0 else MODE_DEFAULTS[self.mode][key]

    @property
    def features(self) -> FeatureSettings:
        return self.settings(
            FeatureSettings,
            flatline_seconds=self.mode_default("flatline_seconds"),
            saturation_fraction=self.mode_default("saturation_fraction"),
            frequency_domain=self.hrv_window_seconds == 0,
        )

    def resolved_output_prefix(self) -> str:
        """The outputs' topic prefix: ``output_prefix``, or the input topic of a ros: input."""
        if self.output_prefix:
            return self.output_prefix.rstrip("/")
        return split_uri(self.input)[1].partition("?")[0].rstrip("/")

    def resolved_lsl_prefix(self) -> str:
        return self.lsl_prefix or self.resolved_output_prefix()


_SEED_NUMBERS = {"buffer": TypeAdapter(int), "window": TypeAdapter(int), "sampling_rate": TypeAdapter(float)}


def _number(value: Any, key: str, source: str) -> Any:
    """A number needed to translate the seed's keys (pydantic converts it); ConfigError naming the key."""
    try:
        if isinstance(value, bool):
            raise ValueError("a boolean is not a number")
        return _SEED_NUMBERS[key].validate_python(value)
    except (ValidationError, ValueError):
        kind = "an integer" if key != "sampling_rate" else "a number"
        raise ConfigError(f"{source}: {key}: expected {kind}, got {value!r}") from None
