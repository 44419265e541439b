"""Sensor identification: the bias-model fit (biasfit), residual whiteness tests
(whiteness) and noise figures from the Allan deviation (noiseid)."""

# its modules, which users import by name (``from accelnav.identify import allan``)
__all__ = [
    "allan",
    "biasfit",
    "calibrate",
    "calibration",
    "characterise",
    "noisecomp",
    "noiseid",
    "quantised",
    "whiteness",
]
