"""Model -> Q formats -> C text (pure functions). Stands on accelnav.model and accelnav.native only."""

# its modules, which users import by name (``from accelnav.codegen import arduino``)
__all__ = [
    "arduino",
    "bounds",
    "emit_c",
    "emit_f32",
    "follow",
    "frames",
    "gains",
    "generated",
    "package",
    "qformat",
    "ranges",
    "report",
    "targets",
]
