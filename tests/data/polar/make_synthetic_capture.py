"""Build synthetic_h10.jsonl: a SYNTHETIC capture of a Polar H10, made from the test vectors of issue 13.

Nothing here was recorded from a real strap. The file has the exact shape the streamer's
``--capture`` writes, so it exercises the replay path end to end:

- the feature read (ECG + ACC) and a battery read (90 %);
- ECG: the get-settings answer (130 Hz, 14 bit), the start request of the issue
  ``02 00 00 01 82 00 01 01 0E 00`` and its answer ``F0 02 00 00 00 00``;
- ACC: get-settings (25/50/100/200 Hz, 16 bit, 2/4/8 G), start at 25 Hz / 8 G, answer;
- 10 s of data: ECG frames of 8 samples (the first is the issue's ECG vector byte for byte, the
  others repeat its 8 values with timestamps advancing 8 / 130 s on the same device clock),
  ACC frames of 2 samples at 25 Hz (the issue's ACC payload (-187, -28, 949), (-187, -28, 952)
  with timestamps on the ECG's device clock; the vector's own timestamp is from another
  recording), and the issue's HR notification ``10 48 DB 03 C5 03`` once a second;
- host receive times: 20 ms after each frame's last sample, plus a fixed pattern of 0-9 ms.

Run ``python tests/data/polar/make_synthetic_capture.py`` to rebuild it; a test checks that the
shipped file is exactly what this script makes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUTPUT = HERE / "synthetic_h10.jsonl"

ECG_VECTOR = bytes.fromhex("00EA1CACCC99435208006800005800004600003D0000320000260000160000040000")
ACC_VECTOR = bytes.fromhex("02EA54A2428B4552080145FFE4FFB50345FFE4FFB803")
HR_VECTOR = bytes.fromhex("1048DB03C503")
START_ECG = bytes.fromhex("02000001820001010E00")
START_ECG_RESPONSE = bytes.fromhex("F00200000000")
SECONDS = 10
HOST_START = 5000.0
NS = 1_000_000_000


def build_lines() -> list[str]:
    sys.path.insert(0, str(HERE.parents[2] / "src" / "hri_physio_bridge"))
    from hri_physio_bridge.polar import control_point as cp
    from hri_physio_bridge.polar.capture import FORMAT, VERSION, CaptureRecord
    from hri_physio_bridge.polar.gatt import (
        BATTERY_LEVEL,
        HEART_RATE_MEASUREMENT,
        PMD_CONTROL_POINT,
        PMD_DATA,
    )
    from hri_physio_bridge.polar.protocol import Measurement

    header = {
        "format": FORMAT,
        "version": VERSION,
        "synthetic": True,
        "note": "SYNTHETIC: built by make_synthetic_capture.py from the test vectors of issue 13; "
        "not a recording of a real strap",
        "device": {"name": "Polar H10 0A1B2C3D", "address": "A0:9E:1A:00:00:01"},
    }
    lines = [json.dumps(header)]
    t = HOST_START

    def add(op: str, char: str, data: bytes, at: float) -> None:
        lines.append(CaptureRecord(at, op, char, data).to_json())

    add("read", PMD_CONTROL_POINT, cp.encode_features({Measurement.ECG, Measurement.ACC}), t)
    add("read", BATTERY_LEVEL, bytes([90]), t + 0.01)
    ecg_settings = cp.encode_offered_settings(
        {cp.SettingType.SAMPLE_RATE: [130], cp.SettingType.RESOLUTION: [14]}
    )
    acc_settings = cp.encode_offered_settings(
        {
            cp.SettingType.SAMPLE_RATE: [25, 50, 100, 200],
            cp.SettingType.RESOLUTION: [16],
            cp.SettingType.RANGE: [2, 4, 8],
        }
    )
    add("write", PMD_CONTROL_POINT, cp.get_settings_request(Measurement.ECG), t + 0.02)
    add(
        "notify",
        PMD_CONTROL_POINT,
        cp.encode_response(cp.OpCode.GET_SETTINGS, Measurement.ECG, params=ecg_settings),
        t + 0.03,
    )
    add("write", PMD_CONTROL_POINT, START_ECG, t + 0.04)
    add("notify", PMD_CONTROL_POINT, START_ECG_RESPONSE, t + 0.05)
    add("write", PMD_CONTROL_POINT, cp.get_settings_request(Measurement.ACC), t + 0.06)
    add(
        "notify",
        PMD_CONTROL_POINT,
        cp.encode_response(cp.OpCode.GET_SETTINGS, Measurement.ACC, params=acc_settings),
        t + 0.07,
    )
    acc_start = cp.start_request(
        Measurement.ACC,
        {cp.SettingType.SAMPLE_RATE: 25, cp.SettingType.RESOLUTION: 16, cp.SettingType.RANGE: 8},
    )
    add("write", PMD_CONTROL_POINT, acc_start, t + 0.08)
    add("notify", PMD_CONTROL_POINT, cp.encode_response(cp.OpCode.START, Measurement.ACC), t + 0.09)

    data: list[tuple[float, str, bytes]] = []
    stream_start = t + 0.1
    ecg_t0 = int.from_bytes(ECG_VECTOR[1:9], "little")
    first_sample = ecg_t0 - (7 * NS * 2 + 130) // 260  # device time of the vector's first sample
    for k in range(SECONDS * 130 // 8):
        last = first_sample + ((8 * k + 7) * NS * 2 + 130) // 260
        frame = ECG_VECTOR[:1] + last.to_bytes(8, "little") + ECG_VECTOR[9:]
        host = stream_start + (last - first_sample) / NS + 0.020 + (k * 7 % 10) / 1000
        data.append((host, PMD_DATA, frame))
    acc_payload = ACC_VECTOR[9:]
    for k in range(SECONDS * 25 // 2):
        last = first_sample + (2 * k + 1) * NS // 25
        frame = ACC_VECTOR[:1] + last.to_bytes(8, "little") + acc_payload
        host = stream_start + (last - first_sample) / NS + 0.020 + (k * 3 % 10) / 1000
        data.append((host, PMD_DATA, frame))
    for k in range(SECONDS):
        data.append((stream_start + 1.0 + k + 0.015, HEART_RATE_MEASUREMENT, HR_VECTOR))
    for host, char, frame in sorted(data, key=lambda item: item[0]):
        add("notify", char, frame, host)
    return lines


def main() -> None:
    OUTPUT.write_text("\n".join(build_lines()) + "\n", encoding="utf-8")
    print(f"wrote {OUTPUT}")


if __name__ == "__main__":
    main()
