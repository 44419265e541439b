# Everything about the distribution is in pyproject.toml. This file exists only
# because cffi's build hook (cffi_modules) has no pyproject.toml form: it
# compiles the C kernels into the wheel (host/native/kernels.py), so that a
# plain install needs no C compiler for the smoother, codegen's gain recursion
# and schedule search, the telemetry decoder's frame kernel and the CSV reader's numbers.
from setuptools import setup

setup(
    # the kernels use only Python's limited API (cffi builds them so): one wheel serves 3.11 and later
    options={"bdist_wheel": {"py_limited_api": "cp311"}},
    cffi_modules=[
        "host/native/kernels.py:smoother",
        "host/native/kernels.py:riccati",
        "host/native/kernels.py:wire",
        "host/native/kernels.py:csvnum",
    ],
)
