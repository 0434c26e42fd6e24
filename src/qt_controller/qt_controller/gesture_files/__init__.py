"""Data package: the exercise gesture keyframe files (*.xml) shipped with qt_controller.

A package of its own so ``importlib.resources.files("qt_controller.gesture_files")`` finds
the files in every kind of install (wheel, editable, colcon), whatever else is on sys.path.
"""
