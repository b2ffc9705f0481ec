"""Collection on a robot: a calibration policy drives an arm holding a camera + IMU and the data are recorded.

``runner``: ``Collector`` aligns the camera with the board, runs the policy with the env's own state
code on the live data and writes the recording as it arrives (``vical-collect``,
docs/tutorial-real-robot.md). The arm and sensor it drives are ``vical.robot``'s interfaces.
"""
