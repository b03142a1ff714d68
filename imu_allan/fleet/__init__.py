"""
Fleets: the offline analysis of many IMUs' recordings on Dask, a store, and fleet views.

``imu-allan fleet`` (:mod:`imu_allan.cli.fleet`) runs today's per-input pipeline
(:func:`imu_allan.io.inputs.analyze_input`, unchanged) over many bags on a Dask cluster
(:mod:`.run`: a local one by default, a real one with ``--scheduler``), keys every result
by IMU identity, recording start and file content (:mod:`.inputs`), appends it to a
Parquet store (:mod:`.store`), and compares the IMUs with their siblings and with their
own history (:mod:`.views`, :mod:`.report`).

An optional extra (``pip install imu_allan[fleet]``: dask[distributed] and pyarrow):
only this package imports them, lazily; the core, the pipeline and the node never do.
"""
