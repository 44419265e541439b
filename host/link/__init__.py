"""The telemetry link: frame decoding and encoding (telemetry), the serial recorder
(recorder) and its crash-safe log (logfile)."""
