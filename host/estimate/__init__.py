"""Estimation: the float64 reference filter and RTS smoother (kf), the compiled smoother
(fastsmooth, with its C in csrc/), zero-velocity detection (zupt), position fixes (fixes)
and the run-level chain the commands share (pipeline)."""
