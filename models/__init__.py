"""The model files shipped with accelnav (package data; see accelnav.codegen.resources)."""
