"""The AVR routines of the fixed-point runtime (acn_avr_smac, acn_avr_umac, acn_avr_rshr32,
acn_avr_hi_round, acn_avr_add_sat32: hand-written assembly in codegen/csrc/acn_runtime.h) give the
integers their C contracts define.

The runtime's helpers (acn_mul, acn_mac, acn_mac_hi, acn_umulhi, acn_umul, acn_rshr32, acn_mul_rshr32,
acn_hi_round, acn_add_sat32) run on a table of operands (the int32 and int64 edges, every shift count
1..63, seeded random values) in simavr and on the host (the plain C of the same helpers); both are
compared with the exact integers computed here in Python. The filters' own runs (test_avr_portable)
reach only the operands a filter produces; the edges and the saturation path are here.

Skipped, with the reason, without avr-gcc / simavr; under ACCELNAV_REQUIRE_AVR=1 (CI) a failure.
"""

from __future__ import annotations

import random

import pytest

from accelnav.codegen.emit_c import runtime_text
from accelnav.hil_sim.targets import simavr

pytestmark = pytest.mark.usefixtures("avr_tools")

M32, M64 = 2**32, 2**64
I32 = (-(2**31), -(2**31) + 1, -(2**16), -1, 0, 1, 2**15, 2**16 - 1, 2**31 - 1)
I64 = (-(2**63), -(2**63) + 1, -(2**32), -(2**31), -1, 0, 1, 2**31 - 1, 2**31, 2**32 - 1, 2**62, 2**63 - 1)


def _in_contract(acc: int, a: int, b: int, s: int) -> int:
    """acc moved toward zero until acc + a b and acc + 2^(s-1) fit int64 (the helpers' contracts: the C
    of acn_mac and ACN_RSHR adds in int64)."""
    while not -(2**63) <= acc + a * b < 2**63 or acc + 2 ** (s - 1) >= 2**63:
        acc //= 2
    return acc


def _cases() -> list[tuple[int, int, int, int]]:
    """(acc, a, b, s): every edge pair of a and b, the int64 edges, every shift count, then random."""
    rng = random.Random(34)
    out = []
    for i, a in enumerate(I32):
        for j, b in enumerate(I32):
            out.append((I64[(i + j) % len(I64)], a, b, 1 + (i * len(I32) + j) % 63))
    for k in range(160):
        acc = rng.randrange(-(2**63), 2**63) >> rng.randrange(0, 63)
        a = rng.randrange(-(2**31), 2**31) >> rng.randrange(0, 31)
        b = rng.randrange(-(2**31), 2**31) >> rng.randrange(0, 31)
        out.append((acc, a, b, 1 + k % 63))
    return [(_in_contract(*c), *c[1:]) for c in out]


def _expected(acc: int, a: int, b: int, s: int) -> str:
    """The record the driver prints for one case, from the helpers' contracts."""
    mac = (acc + a * b) % M64
    total = a + b
    sat = min(max(total, -(2**31)), 2**31 - 1)
    fields = [
        (a * b) % M64,  # acn_mul
        mac,  # acn_mac
        mac >> 32,  # acn_mac_hi
        ((a % M32) * (b % M32)) >> 32,  # acn_umulhi
        (a % M32) * (b % M32),  # acn_umul
        ((acc + 2 ** (s - 1)) >> s) % M32,  # acn_rshr32: the exact rounded shift, its low word
        ((a * b + 2 ** (s - 1)) >> s) % M32,  # acn_mul_rshr32
        ((acc % M64 + 2**31) % M64) >> 32,  # acn_hi_round
        sat % M32,  # acn_add_sat32
        int(sat != total),  # ... and its count
    ]
    widths = (16, 16, 8, 8, 16, 8, 8, 8, 8, 8)
    return "R" + "".join(f"{v:0{w}x}" for v, w in zip(fields, widths, strict=True))


def _driver(cases) -> str:
    rows = ",\n    ".join(f"{{INT64_C({c[0]}), INT32_C({c[1]}), INT32_C({c[2]}), {c[3]}u}}" for c in cases)
    rows = rows.replace("INT64_C(-9223372036854775808)", "INT64_MIN").replace("INT32_C(-2147483648)", "INT32_MIN")
    return f"""#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include "acn_rt.h"
#if defined(__AVR__)
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>
#include <avr/sleep.h>
static void out(char c)
{{
    while (!(UCSR0A & (1u << UDRE0))) {{
    }}
    UDR0 = (uint8_t)c;
}}
#define GET(d, p) memcpy_P((d), (p), sizeof *(d))
#else
#include <stdio.h>
#define PROGMEM
static void out(char c)
{{
    putchar(c);
}}
#define GET(d, p) memcpy((d), (p), sizeof *(d))
#endif
typedef struct {{
    int64_t acc;
    int32_t a, b;
    uint8_t s;
}} case_t;
static const case_t cases[] PROGMEM = {{
    {rows}}};
static void hex(uint64_t v, unsigned digits)
{{
    while (digits--) {{
        out("0123456789abcdef"[(v >> (4u * digits)) & 15u]);
    }}
}}
int main(void)
{{
#if defined(__AVR__)
    UCSR0A = 1u << U2X0;
    UCSR0B = 1u << TXEN0;
#endif
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {{
        case_t c;
        uint32_t ov = 0;
        GET(&c, &cases[i]);
        out('R');
        hex((uint64_t)acn_mul(c.a, c.b), 16u);
        hex((uint64_t)acn_mac(c.acc, c.a, c.b), 16u);
        hex((uint32_t)acn_mac_hi(c.acc, c.a, c.b), 8u);
        hex(acn_umulhi((uint32_t)c.a, (uint32_t)c.b), 8u);
        hex(acn_umul((uint32_t)c.a, (uint32_t)c.b), 16u);
        hex((uint32_t)acn_rshr32(c.acc, c.s), 8u);
        hex((uint32_t)acn_mul_rshr32(c.a, c.b, c.s), 8u);
        hex((uint32_t)acn_hi_round(c.acc), 8u);
        hex((uint32_t)acn_add_sat32(c.a, c.b, &ov), 8u);
        hex(ov, 8u);
        out(';');
        out('\\n');
    }}
    out('E');
    out(';');
    out('\\n');
#if defined(__AVR__)
    cli();
    sleep_cpu();
#endif
    return 0;
}}
"""


def test_avr_routines_give_the_contracts_integers(tmp_path):
    cases = _cases()
    header = "#include <stdbool.h>\n#include <stdint.h>\n#include <limits.h>\n#include <stddef.h>\n" + runtime_text()
    files = {"acn_rt.h": header}
    drv = _driver(cases)
    want = [_expected(*c) for c in cases]
    avr = simavr.run_avr(files, drv, tmp_path / "avr")
    bad = [(i, cases[i], g, w) for i, (g, w) in enumerate(zip(avr.records, want, strict=True)) if g != w]
    assert len(avr.records) == len(want) and not bad, f"{len(bad)} cases differ on the AVR, the first: {bad[:1]}"
    host = simavr.run_host(files, drv, tmp_path / "host")
    assert host.records == want  # the plain C of the same helpers: the contracts' integers too


def test_the_comparison_catches_a_wrong_routine(tmp_path):
    """A one-instruction slip in the assembly (the signed correction for b < 0 left out) is caught."""
    cases = _cases()
    text = runtime_text()
    slip = "1: sbrs r13, 7\\nrjmp 2f\\n"
    assert text.count(slip) == 1
    header = "#include <stdbool.h>\n#include <stdint.h>\n#include <limits.h>\n#include <stddef.h>\n"
    files = {"acn_rt.h": header + text.replace(slip, "1: rjmp 2f\\n")}
    avr = simavr.run_avr(files, _driver(cases), tmp_path / "avr")
    want = [_expected(*c) for c in cases]
    assert len(avr.records) == len(want)
    assert sum(g != w for g, w in zip(avr.records, want, strict=True)) > 10
