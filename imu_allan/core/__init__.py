"""
The ROS-free core: Allan estimators, noise model, fit, simulation, Kalman outputs.

numpy and scipy only; nothing here imports the pipeline, the I/O adapters or ROS.
"""
