"""Compiling C: the one cffi builder with the project's strict flags, and the kernels built into the wheel.

It knows no filter; the estimators and the generator both use it.
"""

# its modules, which users import by name (``from accelnav.native import cbuild``)
__all__ = [
    "cbuild",
    "kernels",
]
