# Everything about the distribution is in pyproject.toml. This file exists only
# because cffi's build hook (cffi_modules) has no pyproject.toml form: it
# compiles the C kernels into the wheel, so that a plain install needs no C
# compiler for the smoother (host/estimate/fastsmooth_build.py), codegen's gain
# recursion and schedule search (codegen/riccati_build.py) and the telemetry
# decoder's frame kernel (host/link/wirekernel_build.py).
from setuptools import setup

setup(
    cffi_modules=[
        "host/estimate/fastsmooth_build.py:ffibuilder",
        "codegen/riccati_build.py:ffibuilder",
        "host/link/wirekernel_build.py:ffibuilder",
    ]
)
