"""HRI Physio bridge: physiological streams between LSL, ROS 2 and files."""
