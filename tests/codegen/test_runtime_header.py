"""The fixed-point runtime is a real header (codegen/csrc/acn_runtime.h, package data): it compiles on its
own with the strict flags, and the generator copies it into every fixed-point filter (issue 22)."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from accelnav.codegen.emit_c import RUNTIME_HEADER, emit, runtime_text
from accelnav.model.load import load_model
from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.resources import package_dir

CSRC = package_dir("accelnav.codegen") / "csrc"
# a translation unit that includes the header and calls into it: clang warns on unused static inline
# functions only when they are defined in the main file, so the header is included, not compiled as is
USE = """#include "acn_runtime.h"
int64_t acn_runtime_use(int64_t x, int32_t c);
int64_t acn_runtime_use(int64_t x, int32_t c)
{
    uint32_t over = 0;
    int n = 0;
    return acn_limit(acn_mul64x32(x, c, 31), 1, &over) + acn_mac(acn_mul(c, c), c, 3) + (int64_t)acn_recip(7u, &n);
}
"""


@pytest.mark.parametrize("cc", ["gcc", "clang"])
def test_runtime_header_compiles_alone_with_the_strict_flags(cc, tmp_path):
    if shutil.which(cc) is None:
        pytest.skip(f"{cc} not found")
    (tmp_path / "use.c").write_text(USE)
    cmd = [cc, *STRICT_FLAGS, f"-I{CSRC}", "-c", str(tmp_path / "use.c"), "-o", str(tmp_path / "use.o")]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_every_fixed_point_filter_carries_the_runtime(form):
    text = runtime_text()
    assert "acn_mul64x32" in text and "#ifndef ACN_RUNTIME_H" not in text  # the body, not the guard
    assert text in emit(load_model(), form=form)["accelnav.c"]


def test_runtime_header_is_package_data():
    assert (CSRC / RUNTIME_HEADER).is_file()
