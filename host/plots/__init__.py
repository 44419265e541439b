"""Figures a person looks at: a run and its smoothing (run), the bias fit (biasfit)."""
