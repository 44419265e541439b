"""Figures a person looks at: a run and its smoothing (run), the bias fit (biasfit)."""

# its modules, which users import by name (``from accelnav.plots import biasfit``)
__all__ = [
    "biasfit",
    "hil",
    "live",
    "run",
]
