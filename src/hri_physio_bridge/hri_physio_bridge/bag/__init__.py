"""MCAP recording and replay (rosbag2 directories) without rosbag2.

Logic only (no rclpy): :mod:`.writer` (durable MCAP writer), :mod:`.recovery` (read/repair a
bag whose writer died), :mod:`.reader`, :mod:`.metadata` (``metadata.yaml`` v9),
:mod:`.msgdefs`, :mod:`.qos`, :mod:`.topics`, :mod:`.recording` and :mod:`.playback`
(scheduling). The node shells are ``nodes/recorder.py`` and ``nodes/replayer.py``.
"""
