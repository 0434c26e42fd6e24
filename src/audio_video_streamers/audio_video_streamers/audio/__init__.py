"""The audio streamer's logic: synthesis, tracks, the mixer, the sources and the player (no rclpy)."""
