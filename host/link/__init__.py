"""The telemetry link: the frame layout (manifest), frame encoding (codec), loss accounting (accounting),
the streaming decoder (decoder) with the compact mode's stream and replay (compact, replay), the serial
recorder (recorder) and its crash-safe log (logfile)."""

# its modules, which users import by name (``from accelnav.link import accounting``)
__all__ = [
    "accounting",
    "codec",
    "compact",
    "decoder",
    "logfile",
    "manifest",
    "recorder",
    "replay",
    "wirekernel",
]
