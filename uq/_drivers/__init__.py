"""Layer 10: whole pipelines: a catalogue on Dask, the calibration study."""
