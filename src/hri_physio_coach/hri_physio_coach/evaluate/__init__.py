"""Policy evaluation over a simulated cohort, discrete-event (no ROS, no LSL): ``hri_physio_evaluate``."""
