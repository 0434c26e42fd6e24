"""Polar H10 / OH1 / Verity Sense over Bluetooth LE into LSL (see docs/POLAR.md).

Logic (no bleak, rclpy or pylsl): ``protocol`` (notification decoders), ``control_point`` and
``control_channel`` (requests and their answers), ``gatt``, ``mtu``, ``devices``, ``timing``,
``clock_sync`` and ``rate_check`` (per-sample timestamps, effective rates), ``data_path``
(notifications to samples), ``watchdog``, ``session`` (the connection life cycle), ``capture``,
``config``, ``output``, ``encode``, ``fake``, ``virtual_time`` and ``synthetic`` (the fake device).
Boundaries: ``bleak_ble`` (bleak) and ``lsl_output`` (pylsl).
"""
