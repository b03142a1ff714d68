"""Storage readers of :mod:`imu_allan.io.bag_reader`, one module per storage."""
