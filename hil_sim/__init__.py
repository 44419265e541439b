"""The simulator (sim/) and the runners that drive the generated C in-process and on emulated boards (targets/)."""
