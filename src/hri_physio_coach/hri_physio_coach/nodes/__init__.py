"""Node shells (rclpy) of hri_physio_coach."""
