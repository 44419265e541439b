"""The model files shipped with accelnav (package data; see accelnav.resources)."""

__all__: list[str] = []  # data only: nothing to import
