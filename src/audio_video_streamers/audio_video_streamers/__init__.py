"""The audio and video streamers: what the participant hears and sees, driven by the coach.

Logic (no rclpy): :mod:`.requests` (what a request names), :mod:`.status` (the status model),
:mod:`.pacing` (time on an injected clock), :mod:`.audio` and :mod:`.video`. The ROS shells
are in :mod:`.nodes`.
"""
