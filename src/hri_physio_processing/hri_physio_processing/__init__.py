"""Processing and analysis of physiological streams (logic modules import no rclpy).

filters: streaming Butterworth biquads; transforms: Hilbert transform and spectrogram;
windowing: sliding windows over timestamped chunks; signal_checks and features: NeuroKit2
features per window with validity rules; processor: the neurokit_processor node's logic;
pipeline: its input loop (open or wait for the input, process, reopen when lost); config: its options.
"""
