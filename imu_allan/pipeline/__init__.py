"""
One analysis path for live and offline data.

The session (input hygiene, accumulation, checkpoints) and the analysis of an
accumulated curve; fed the same way by the node and by the offline readers.
"""
