"""Compiling C: the one cffi builder with the project's strict flags, and the kernels built into the wheel.

It knows no filter; the estimators and the generator both use it.
"""
