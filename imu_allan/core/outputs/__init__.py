"""
What the fitted model becomes for its consumers.

:mod:`.kalman` (Q/R of the bias model, Imu covariances), :mod:`.exports` (Kalibr,
robot_localization, VINS, OpenVINS and driver files).
"""
