"""accelnav: short-duration position from a cheap accelerometer.

One import name for the whole toolkit. The source folders map onto it:

* ``accelnav.cli``       the ``accelnav`` command, one module per subcommand (host/cli/)
* ``accelnav.estimate``  reference filter, compiled smoother, ZUPT, fixes (host/estimate/)
* ``accelnav.identify``  bias fit, whiteness, noise figures (host/identify/)
* ``accelnav.link``      telemetry frames, recorder, log (host/link/)
* ``accelnav.data``      recordings in, run files (host/data/)
* ``accelnav.plots``     figures (host/plots/)
* ``accelnav.hil_sim``   simulator, SIL and PIL runners (hil_sim/)
* ``accelnav.codegen``   model file -> fixed-point C, and the one cffi builder (codegen/)
* ``accelnav.models``, ``accelnav.firmware``: package data (models/, firmware/)

Layers, top to bottom: cli -> hil_sim -> estimate, identify, link, data, plots -> codegen.
Nothing imports upward (tests/test_layers.py checks it).
"""

__version__ = "0.1.0"
