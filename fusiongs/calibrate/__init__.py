"""Contrast thresholds of an event sensor from frames and events: options, estimator, its data, fits,
pixel model and per-channel pooling (``fusiongs calibrate``)."""
