"""Node shells (rclpy): qt_controller and mock_qt_robot console scripts."""
