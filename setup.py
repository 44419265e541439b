# Everything about the distribution is in pyproject.toml. This file exists only
# because cffi's build hook (cffi_modules) has no pyproject.toml form: it
# compiles the smoother's C kernel into the wheel (see host/estimate/fastsmooth_build.py).
from setuptools import setup

setup(cffi_modules=["host/estimate/fastsmooth_build.py:ffibuilder"])
