"""Every node of a session and the configuration it starts with, checked before anything starts (no rclpy).

:func:`plan_session` turns the launcher's options into one :class:`NodeLaunch` per process:
its console script and its resolved configuration (the node's own model, so the check is the
node's own). Each configuration is written to the session folder (``configs/<node>.yaml``) and
given to the node with ``--conf``: what is kept is what ran. Anything invalid - an option, the
coach's YAML, the routine, a routine that does not fit the coach - raises
:class:`~hri_physio_bridge.config.ConfigError` before a process is started or a bag created.

Media: ``audio_streamer`` (null sink unless ``--audio-sink`` says otherwise) and ``video_streamer``
(offscreen) play what the coach asks for, on the session's clock; so the mock robot no longer
mirrors media requests as its own events (``mirror_media: false``): the streamers' status topics
say what played. Heart rate comes from the simulated participant, or with ``--source polar:<id>``
from ``polar_streamer`` and a real Polar H10 (``polar-replay:<capture>`` replays a capture).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from audio_video_streamers.audio.config import AudioStreamerConfig
from audio_video_streamers.video.config import VideoStreamerConfig
from hri_physio_bridge import topics
from hri_physio_bridge.bag.options import RecorderConfig
from hri_physio_bridge.config import ConfigError, NodeConfig
from hri_physio_bridge.polar.capture import CaptureError, read_capture
from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.devices import device_id_of
from hri_physio_bridge.receiver import ReceiverConfig
from hri_physio_bringup.clock import CLOCK_STEP
from hri_physio_bringup.folder import SessionFolder
from hri_physio_bringup.live import LIVE_NODE, LiveViewConfig
from hri_physio_bringup.options import SessionConfig
from hri_physio_coach.coach import CoachError, ExerciseCoach
from hri_physio_coach.config import COACH_NODE, CoachNodeConfig
from hri_physio_coach.participant_config import PARTICIPANT_NODE, ParticipantNodeConfig
from hri_physio_coach.paths import default_config_file
from hri_physio_coach.routine import RoutineError
from hri_physio_processing.config import ProcessorConfig
from qt_controller.config import MockQtRobotConfig, QtControllerConfig

#: Valid HR samples a rule update needs when the coach listens to the processor's HR (one per 5 s hop).
ECG_HR_MIN_SAMPLES = 3
#: Seconds without HR before the coach pauses adaptation, on the processor's HR (4 hops).
ECG_HR_TIMEOUT = 20.0
SIM_TIME = ("-p", "use_sim_time:=true")

RECORDER, MOCK, CONTROLLER = "physio_recorder", "mock_qt_robot", "qt_controller"
HR_RECEIVER, ECG_RECEIVER, PROCESSOR = "hr_receiver", "ecg_receiver", "neurokit_processor"
PARTICIPANT, COACH = PARTICIPANT_NODE, COACH_NODE
AUDIO, VIDEO, POLAR_STREAMER = "audio_streamer", "video_streamer", "polar_streamer"
LIVE = LIVE_NODE
#: Which part of a lab (``--role``) runs each node.
ROLE_OF = {RECORDER: "station", LIVE: "station", MOCK: "robot", CONTROLLER: "robot", AUDIO: "robot",
           VIDEO: "robot", PARTICIPANT: "sensor", POLAR_STREAMER: "sensor", HR_RECEIVER: "station",
           ECG_RECEIVER: "station", PROCESSOR: "station", COACH: "station"}
#: Frames the audio streamer renders at once on the null sink: at 30x sim time, ~320 blocks per wall second.
NULL_SINK_BLOCK = 4096


@dataclass(frozen=True)
class NodeLaunch:
    """One process of the session."""

    name: str  # the ROS node's name: also its log file, its config file and its console label
    script: str  # the console script
    prog: str  # the section of the --conf file the node reads (its program name)
    config: NodeConfig
    extra: tuple[str, ...] = ()  # arguments after --conf (ROS arguments)

    def config_yaml(self) -> str:
        return self.config.to_yaml(self.prog)

    def argv(self, conf: Path) -> list[str]:
        return ["--conf", str(conf), *self.extra]


@dataclass(frozen=True)
class SessionPlan:
    coach: CoachNodeConfig
    routine_duration: float  # session seconds from start to the routine's end
    device_id: str
    nodes: tuple[NodeLaunch, ...]
    #: (topic, node) pairs: the session starts once each node subscribes to its topic (no request lost).
    listeners: tuple[tuple[str, str], ...] = ()
    #: The simulated participant's reaction period (s; 0: no simulated participant, or one reacting at once).
    reaction_period: float = 0.0

    @property
    def hr_topic(self) -> str:
        return self.coach.hr_topic

    def node(self, name: str) -> NodeLaunch:
        return next(n for n in self.nodes if n.name == name)

    @property
    def receivers(self) -> dict[str, tuple[str, float]]:
        """Each receiver's ROS output topic and sampling rate, by node name."""
        return {n.name: (n.config.output.removeprefix("ros:"), float(n.config.sampling_rate))
                for n in self.nodes if isinstance(n.config, ReceiverConfig)}


def coach_config(options: SessionConfig) -> CoachNodeConfig:
    """The coach's configuration: its YAML (or the packaged one) < what the session sets."""
    overrides: dict[str, Any] = {
        "interactive": True,  # the launcher says 'start' once everything runs
        "part_age": options.age,
        "tick_period": CLOCK_STEP,
        "hr_topic": topics.POLAR_H10_ECG_HR if options.hr_source == "ecg" else topics.POLAR_H10_HR,
    }
    if options.policy is not None:
        overrides["policy"] = options.policy
    if options.routine:
        overrides["routine_file"] = str(Path(options.routine).resolve())
    if options.hr_source == "ecg":
        # One processor HR per 5 s hop: 6 per 30 s rule update, below the strap's default of 10.
        overrides.update(min_valid_samples=ECG_HR_MIN_SAMPLES, hr_timeout=ECG_HR_TIMEOUT)
    conf = Path(options.conf) if options.conf else default_config_file()
    config = CoachNodeConfig.from_file(conf, COACH_NODE, overrides)
    if config.routine_file and not Path(config.routine_file).is_absolute():
        # Relative to where the session was started, not to wherever the coach runs.
        config = config.replace(routine_file=str(Path(config.routine_file).resolve()))
    return config


def check_coach(config: CoachNodeConfig) -> float:
    """Build the coach as the node will (routine loaded, routine and coach fitted together); its duration."""
    try:
        coach = ExerciseCoach(config, lambda: 0.0, lambda _line: None, lambda _event: None)
    except (CoachError, RoutineError) as exc:
        raise ConfigError(f"{COACH_NODE}: {exc}") from None
    return coach.routine.duration


def _validated(cls: type[NodeConfig], name: str, values: Mapping[str, Any]) -> Any:
    return cls.from_mapping(values, name)


def replay_device_id(capture_file: str) -> str:
    """The strap's id in a capture's header (the advertised name, e.g. 'Polar H10 0A1B2C3D')."""
    try:
        header = read_capture(capture_file).header
    except CaptureError as exc:
        raise ConfigError(f"source polar-replay: {exc}") from None
    name = (header.get("device") or {}).get("name") if isinstance(header.get("device"), dict) else None
    device = device_id_of(name)
    if device is None:
        raise ConfigError(f"source polar-replay: {capture_file} names no Polar device id in its header "
                          f"(device name {name!r})")
    return device


def strap_device_id(options: SessionConfig, simulated_id: str) -> str:
    """The device id in the LSL names the receivers resolve: the strap's, or the simulated one."""
    if options.polar_device:
        return options.polar_device.upper()
    if options.polar_replay:
        return replay_device_id(options.polar_replay)
    return simulated_id


def media_nodes(options: SessionConfig, coach: CoachNodeConfig) -> list[NodeLaunch]:
    """The audio and video streamers, on the session's clock, never touching a screen; the audio
    streamer prepares the coach's music before the session (a new tempo then plays at once)."""
    audio: dict[str, Any] = {"sink": options.audio_sink, "preload": coach.music_requests()}
    if options.audio_sink == "null":
        audio["block"] = NULL_SINK_BLOCK
    return [
        NodeLaunch(AUDIO, "audio_streamer", AUDIO, _validated(AudioStreamerConfig, AUDIO, audio),
                   ("--ros-args", *SIM_TIME)),
        NodeLaunch(VIDEO, "video_streamer", VIDEO, _validated(VideoStreamerConfig, VIDEO, {
            "display": "offscreen"}), ("--ros-args", *SIM_TIME)),
    ]


def heart_rate_node(options: SessionConfig, device_id: str) -> NodeLaunch:
    """Who wears the strap: the simulated participant, or polar_streamer with a real (or replayed) one."""
    if not options.polar:
        return NodeLaunch(PARTICIPANT, "simulated_participant", PARTICIPANT,
                          _validated(ParticipantNodeConfig, PARTICIPANT, {
                              "model": options.participant_model, "age": options.age,
                              "seed": options.participant_seed, "device_id": device_id,
                              "update_period": CLOCK_STEP}), ("--ros-args", *SIM_TIME))
    streams = ["hr", "rr"] if options.no_ecg else ["ecg", "hr", "rr"]  # rr: on LSL for the lab's own tools
    values: dict[str, Any] = {"streams": streams}
    if options.polar_replay:
        values["replay"] = str(Path(options.polar_replay).resolve())
    else:
        values["device"] = device_id
    # On wall time: the strap's samples are stamped on the LSL clock, not on the session's /clock.
    return NodeLaunch(POLAR_STREAMER, "polar_streamer", POLAR_STREAMER,
                      _validated(PolarConfig, POLAR_STREAMER, values))


def plan_session(options: SessionConfig, folder: SessionFolder, device_id: str,
                 coach: CoachNodeConfig | None = None) -> SessionPlan:
    """Every node's configuration for this session, in start order (raises ConfigError).

    ``device_id`` is the simulated strap's; with a Polar source the strap's own id is used.
    """
    coach = coach if coach is not None else coach_config(options)
    duration = check_coach(coach)
    device_id = strap_device_id(options, device_id)
    record = not options.no_record
    nodes: list[NodeLaunch] = []
    if record:
        nodes.append(NodeLaunch(RECORDER, "physio_recorder", RECORDER, _validated(RecorderConfig, RECORDER, {
            "output": str(folder.bag), "session_id": coach.participant,
            "discovery_period": 0.2, "status_period": 10.0})))
    live = options.live_address
    if live is not None:
        # The live view subscribes to a topic only while a viewer watches it, so nothing waits for it (a
        # viewer sees the session from when it connects) and it costs nothing unwatched. On wall time:
        # under sim time it would take every /clock message (hundreds a second at 30x) for nobody.
        host, port = live
        nodes.append(NodeLaunch(LIVE, "live_view", LIVE, _validated(LiveViewConfig, LIVE, {
            "host": host, "port": port, "name": f"HRI Physio session {coach.participant}"})))
    nodes.append(NodeLaunch(MOCK, "mock_qt_robot", MOCK, _validated(MockQtRobotConfig, MOCK, {
        "joint_state_rate": round(1 / CLOCK_STEP, 3), "mirror_media": False}), ("--ros-args", *SIM_TIME)))
    nodes.append(NodeLaunch(CONTROLLER, "qt_controller", CONTROLLER,
                            _validated(QtControllerConfig, CONTROLLER, {}), ("--ros-args", *SIM_TIME)))
    nodes.extend(media_nodes(options, coach))
    nodes.append(heart_rate_node(options, device_id))
    # Each receiver holds its input until all of its listeners are there, so the bag and the
    # coach (or processor) get every sample from the first - also after a restart: HR goes to the
    # launcher's watcher, the recorder and (strap source) the coach; ECG to the processor and the
    # recorder; and each output to the launcher's supervision (where a restarted receiver's gap ends).
    watched = 1
    streams = [(HR_RECEIVER, "HR", topics.POLAR_H10_HR, 1, 1.0,
                watched + 1 + record + (options.hr_source == "strap"))]
    if not options.no_ecg:
        # ECG frames of 0.1 s of wall time (13 samples at 1x): at 30x that is 10 frames a second, not 300,
        # which the processor's and the recorder's subscriptions take with ease on a loaded machine.
        ecg_frame = max(13, round(13 * options.speed))
        streams.append((ECG_RECEIVER, "ECG", topics.POLAR_H10_ECG, ecg_frame, 130.0, watched + 1 + record))
    # In a lab the strap's samples come from the sensor host's LSL clock: the station's receivers add
    # LSL's time correction (the offset of that clock from the station's, measured by liblsl) to them.
    sync = "?sync=1" if options.lab else ""
    for name, stream, topic, frame, rate, listeners in streams:
        values: dict[str, Any] = {
            "input": f"lsl:PolarH10/{device_id}/{stream}{sync}", "output": f"ros:{topic}",
            "output_frame": frame,
            "sampling_rate": rate, "resolve_timeout": options.startup_timeout,
            "wait_for_consumers": options.startup_timeout, "min_consumers": listeners,
        }
        if options.log_data:
            values.update(log_data=True, log_name=str(folder.csv_dir / f"{stream.lower()}.csv"))
        receiver = _validated(ReceiverConfig, name, values)
        nodes.append(NodeLaunch(name, "physio_receiver", "physio_receiver", receiver,
                                ("--ros-args", "-r", f"__node:={name}")))
    if not options.no_ecg:
        processor = _validated(ProcessorConfig, PROCESSOR, {"input": f"ros:{topics.POLAR_H10_ECG}"})
        nodes.append(NodeLaunch(PROCESSOR, "neurokit_processor", PROCESSOR, processor))
    nodes.append(NodeLaunch(COACH, "qt_physio_coach", COACH, coach, ("--ros-args", *SIM_TIME)))
    listeners = [(topics.QT_COMMANDS, CONTROLLER), (topics.COACH_CONTROL, COACH),
                 (topics.QT_SPEECH_SAY, MOCK), (topics.AUDIO_REQUEST, AUDIO), (topics.VIDEO_REQUEST, VIDEO)]
    if not options.polar:
        listeners += [(topics.QT_COMMANDS, PARTICIPANT), (topics.AUDIO_STATUS, PARTICIPANT)]
    if record:
        # The recorder subscribes to a topic once it discovers it: the session starts only once it records
        # every topic a node of the session publishes from its start (the coach's session_start, the
        # first commands and replies, the streamers' and the mock's first statuses, the processor's
        # outputs). The sample frames are held by their receivers until the recorder listens.
        capture = f"{RECORDER}_capture"
        recorded = [topics.COACH_EVENTS, topics.COACH_STATE, topics.QT_COMMANDS, topics.QT_REPLIES,
                    topics.QT_MOCK_EVENTS, topics.AUDIO_STATUS, topics.VIDEO_STATUS, topics.VIDEO_PREVIEW,
                    topics.AUDIO_CURRENT, topics.VIDEO_CURRENT, topics.SESSION_EVENTS]
        if not options.polar:
            recorded.append(topics.PARTICIPANT_STATE)
        if not options.no_ecg:
            recorded += [topics.POLAR_H10_ECG_HR, f"{topics.POLAR_H10_ECG}/status"]
        listeners += [(topic, capture) for topic in recorded]
    participant = next((n.config for n in nodes if n.name == PARTICIPANT), None)
    reaction = participant.params.reaction_period if isinstance(participant, ParticipantNodeConfig) else 0.0
    return SessionPlan(coach, duration, device_id, tuple(nodes), tuple(listeners), reaction)


def listener_role(node: str) -> str | None:
    """The role whose node listens in a plan's (topic, node) pair (the recorder's capture: the station)."""
    return ROLE_OF.get(node.removesuffix("_capture"))


def for_role(plan: SessionPlan, role: str) -> SessionPlan:
    """The nodes one host of a lab runs (``role``), in start order; the listeners stay: the station
    waits for every host's nodes to listen before it starts the session."""
    nodes = tuple(n for n in plan.nodes if ROLE_OF[n.name] == role)
    return replace(plan, nodes=nodes)
