"""The video streamer's logic: rendered screens, file playback, the player and the displays (no rclpy)."""
