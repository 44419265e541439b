"""Where the generated C runs: in-process (SIL, cffi), on emulated boards (PIL), and the per-axis harness."""
