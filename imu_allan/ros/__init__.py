"""
The ROS 2 adapter.

The live node and its parameter table.
"""
