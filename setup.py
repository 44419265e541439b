# Everything about the distribution is in pyproject.toml. This file exists only
# because cffi's build hook (cffi_modules) has no pyproject.toml form: it
# compiles the C kernels into the wheel (codegen/kernel_build.py), so that a
# plain install needs no C compiler for the smoother, codegen's gain recursion
# and schedule search, and the telemetry decoder's frame kernel.
from setuptools import setup

setup(
    cffi_modules=[
        "codegen/kernel_build.py:smoother",
        "codegen/kernel_build.py:riccati",
        "codegen/kernel_build.py:wire",
    ]
)
