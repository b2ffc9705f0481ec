"""An IMU's noise from a static recording (``vical-imu-noise``): Allan deviation and the Kalibr noise parameters
read from it, with its plot."""
