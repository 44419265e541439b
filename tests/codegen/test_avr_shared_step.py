"""On AVR the axes of a covariance model share one copy of the step, each axis' constants and shift
counts in its own table in flash (codegen.share); elsewhere each axis keeps its own step. The shared
step gives the bits of each axis' own, sample by sample: the host runs the per-axis steps, simavr the
shared one.

Skipped, with the reason, without avr-gcc / simavr; under ACCELNAV_REQUIRE_AVR=1 (CI) a failure.
"""

from __future__ import annotations

import re

import pytest
from conftest import MODELS

from accelnav.codegen.emit_c import emit
from accelnav.codegen.share import Shared, merge
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import simavr
from accelnav.model.load import loads_model

SAMPLES = 400
# a third axis with its own bias constants and time constant, as fit-bias writes them: its formats, and
# so its shifts, differ from x's
Z_AXIS = '[[axes]]\nname = "z"\nc1 = 0.03\nc2 = -0.07\nT = 410.0\nzero_g_v = 2.497\n\n'


def _three_axes():
    text = (MODELS / "adxl250_default.toml").read_text()
    return loads_model(text.replace("[noise]", Z_AXIS + "[noise]", 1), source="three_axes")


def test_three_axes_share_one_step_bit_identical_on_avr(tmp_path, avr_tools):
    model = _three_axes()
    files = {k: v for k, v in emit(model, form="covariance").items() if k.endswith((".c", ".h"))}
    src = files["accelnav.c"]
    assert "AVR: axes x, y, z share one copy of the covariance step" in src
    table = re.search(r"typedef struct \{\n(.*?)\} accelnav__k_t;", src, re.S)
    assert table and "uint8_t" in table[1], "the axes differ in shift counts: the table carries them"
    stim = simulate(model, "stress", SAMPLES / model.rate_hz, 3).code.copy()
    stim[40, 0] = 0  # the low rail: a skip, the coarse step's path
    stim[41:44, 2] = 0  # three skips in a row on z
    drv = simavr.driver_c("accelnav.h", files["accelnav.h"], stim, duty=False)
    host = simavr.run_host(files, drv, tmp_path / "host")
    avr = simavr.run_avr(files, drv, tmp_path / "avr")
    assert len(avr.records) == len(host.records) == SAMPLES * 3
    first = next((i for i, (a, h) in enumerate(zip(avr.records, host.records, strict=True)) if a != h), None)
    assert first is None, f"the shared step differs from the axis' own at record {first}"


def test_merge_takes_numbers_into_typed_fields():
    a = "void f(t *s) { s->a = acn_mac(INT64_C(5), s->b >> 3, INT32_C(-7)); s->c += INT32_C(1) << 2; }"
    b = "void f(t *s) { s->a = acn_mac(INT64_C(6), s->b >> 4, INT32_C(-7)); s->c += INT32_C(1) << 2; }"
    sh = merge([a, b])
    assert isinstance(sh, Shared)
    assert sh.members == ["int64_t f0;", "uint8_t f1;"]
    assert sh.inits == [["INT64_C(5)", "3"], ["INT64_C(6)", "4"]]
    assert "ACN_ROM_I64(&acn_k->f0)" in sh.text and ">> ACN_ROM_U8(&acn_k->f1)" in sh.text
    assert "INT32_C(-7)" in sh.text  # the same in both: stays in the code


def test_merge_shares_one_field_for_one_pair_of_values():
    a = "x = INT32_C(1) + INT32_C(1); y = INT32_C(9);"
    b = "x = INT32_C(2) + INT32_C(2); y = INT32_C(9);"
    sh = merge([a, b])
    assert isinstance(sh, Shared) and sh.members == ["int32_t f0;"]


@pytest.mark.parametrize(
    "a,b,said",
    [
        ("x = y >> 3;", "x = y;", "differ in shape"),
        ("x = y + 1;", "x = y - 1;", "+ / -"),
        ("x = y >> 3;", "x = y >> 300;", "3 / 300"),  # beyond uint8_t: not a shift count
        ("x = y + 70000u;", "x = y + 5u;", "70000u / 5u"),  # suffixed: its type depends on its value
        ("x = INT32_C(1);", "x = INT64_C(1);", "INT32_C(1) / INT64_C(1)"),
    ],
)
def test_merge_refuses_what_is_more_than_a_number(a, b, said):
    why = merge([a, b])
    assert isinstance(why, str) and said in why


def test_merge_takes_int32_min_beside_int32_c():
    sh = merge(["x = INT32_MIN;", "x = INT32_C(3);"])
    assert isinstance(sh, Shared) and sh.members == ["int32_t f0;"] and sh.inits == [["INT32_MIN"], ["INT32_C(3)"]]


def test_two_alike_axes_share_a_step_whose_table_is_not_empty(tmp_path, avr_tools):
    """Two axes with the same numbers: their table has a member (C has no empty struct) and builds."""
    text = (MODELS / "adxl250_default.toml").read_text()
    head, x, y = re.split(r"(?=^\[\[axes\]\])", text, flags=re.M)
    twin = x.replace('name = "x"', 'name = "w"')
    model = loads_model(head + x + twin + y[y.index("[noise]") :], source="twins")
    files = {k: v for k, v in emit(model, form="covariance").items() if k.endswith((".c", ".h"))}
    assert "AVR: axes x, w share one copy of the covariance step" in files["accelnav.c"]
    _, ram = simavr.object_size(files, tmp_path)  # compiles for the ATmega328P, -Werror
    assert ram == 0
