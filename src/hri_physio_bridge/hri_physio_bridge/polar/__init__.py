"""Polar H10 / OH1 / Verity Sense over Bluetooth LE into LSL (see docs/POLAR.md).

Logic (no bleak, rclpy or pylsl): ``protocol`` (notification decoders), ``control_point``,
``gatt``, ``devices``, ``timing`` and ``clock_sync`` (per-sample timestamps), ``session`` (the
connection life cycle), ``capture``, ``config``, ``output``, ``encode``, ``fake`` and
``synthetic`` (the fake device). Boundaries: ``bleak_ble`` (bleak) and ``lsl_output`` (pylsl).
"""
