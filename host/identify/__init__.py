"""Sensor identification: the bias-model fit (biasfit), residual whiteness tests
(whiteness) and noise figures from the Allan deviation (noiseid)."""
