"""Estimation: the float64 reference filter and RTS smoother (kf), the compiled smoother
(fastsmooth, with its C in csrc/), zero-velocity detection (zupt), position fixes (fixes)
and the run-level chain the commands share (pipeline)."""

# its modules, which users import by name (``from accelnav.estimate import checks``)
__all__ = [
    "checks",
    "chunked",
    "consistency",
    "fastsmooth",
    "fixes",
    "kf",
    "pipeline",
    "tune",
    "zupt",
]
