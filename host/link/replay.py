"""The host's replay of the firmware's filter, for the compact telemetry mode.

Block frames carry the raw input of every sample (ADC codes or T1/T2 counts)
and a 2-bit code per axis (updated, input refused, no capture, missed by the
board); checkpoint frames carry the bytes of each axis' generated state
struct. :class:`Replay` compiles the very C the firmware runs (the generated
``accelnav.c`` of the model, :mod:`accelnav.codegen.emit_c`, built with
:mod:`accelnav.codegen.cbuild` like SIL) together with a small loop that,
for many stretches at once, starts from a state's bytes, steps the filter
through the stretch's inputs exactly as ``firmware/src/app.c`` does (``step``
on the input for codes 0 and 1, ``skip`` for 2 and 3), writes ``r, u, a, e``
of every sample as ``accelnav_AXIS_read`` gives them, and returns the bytes
of the state at the end of each stretch, for the decoder to hold against the
next checkpoint bit for bit. One C call per axis and decoded batch: no
Python loop over samples.
"""

from __future__ import annotations

import numpy as np

from accelnav.codegen.model import Model, loads_model

_KERNEL = """
/* Replay of axis {ax}: stretch j starts from the state bytes init[j], runs samples
 * start[j] .. start[j] + len[j] - 1 and leaves its final state's bytes in fin[j];
 * r, u, a, e of sample k (accelnav_{ax}_read) go to rows + k * stride + off[0..3]
 * (little-endian, as the fields of the host's sample rows), nbad[j] counts the
 * samples whose step verdict (input taken or refused) differs from the code sent. */
void acnr_{ax}(int64_t nseg, const int64_t *start, const int64_t *len, const uint8_t *init, uint8_t *fin,
               const uint8_t *code, const uint32_t *in1, const uint32_t *in2, uint8_t *rows, int64_t stride,
               const int64_t *off, int64_t *nbad)
{{
    int64_t j, k;
    (void)in2;
    for (j = 0; j < nseg; ++j) {{
        accelnav_{ax}_t s;
        int64_t bad = 0;
        memcpy(&s, init + j * (int64_t)sizeof s, sizeof s);
        for (k = start[j]; k < start[j] + len[j]; ++k) {{
            accelnav_{ax}_out_t o;
            if (code[k] <= 1u) {{ /* updated or refused: app.c called step on this input */
                bool ok = accelnav_{ax}_step(&s, {args});
                bad += ok != (code[k] == 0u);
            }} else {{ /* no capture, or missed by the board: predict only */
                accelnav_{ax}_skip(&s);
            }}
            accelnav_{ax}_read(&s, &o);
            memcpy(rows + k * stride + off[0], &o.r, sizeof o.r);
            memcpy(rows + k * stride + off[1], &o.u, sizeof o.u);
            memcpy(rows + k * stride + off[2], &o.a, sizeof o.a);
            memcpy(rows + k * stride + off[3], &o.e, sizeof o.e);
        }}
        memcpy(fin + j * (int64_t)sizeof s, &s, sizeof s);
        nbad[j] = bad;
    }}
}}

size_t acnr_{ax}_size(void)
{{
    return sizeof(accelnav_{ax}_t);
}}
"""

_DECL = (
    "void acnr_{ax}(int64_t nseg, const int64_t *start, const int64_t *len, const uint8_t *init, uint8_t *fin,"
    " const uint8_t *code, const uint32_t *in1, const uint32_t *in2, uint8_t *rows, int64_t stride,"
    " const int64_t *off, int64_t *nbad);\n"
    "size_t acnr_{ax}_size(void);\n"
)


class ReplayError(ValueError):
    """The replay cannot be built for this manifest and model; ``str()`` is one line."""


def _filter_sources(model: Model) -> dict[str, str]:
    """accelnav.{h,c} of the model exactly as the firmware build generates them (cached on disk)."""
    from accelnav.codegen.generated import generated_files

    return {k: v for k, v in generated_files(model).items() if k in ("accelnav.h", "accelnav.c")}


class Replay:
    """The firmware's filter for the axes of ``manifest``, from ``model`` (a Model or its TOML text)."""

    def __init__(self, manifest, model: Model | str):
        from accelnav.codegen.cbuild import build_module

        if isinstance(model, str):
            model = loads_model(model, source="the model text of the recording")
        if model.sha256 != manifest.model_sha256:
            raise ReplayError(
                f"the model text (sha256 {model.sha256[:12]}) is not the firmware's model "
                f"({manifest.model_sha256[:12]}): no replay"
            )
        self.axes = list(manifest.axes)
        self.state_bytes = [int(n) for n in manifest.data["state_bytes"]]
        duty = manifest.input == "duty_cycle"
        args = "acnr_count(in1[k]), acnr_count(in2[k])" if duty else "(int32_t)in1[k]"
        src = ["#include <stdbool.h>", "#include <stdint.h>", "#include <string.h>", '#include "accelnav.h"', ""]
        if duty:
            src += [
                "/* capture counts above INT32_MAX are no period the filter accepts (firmware/src/filter_adapter.c) */",
                "static int32_t acnr_count(uint32_t c)",
                "{",
                "    return c > (uint32_t)INT32_MAX ? INT32_MAX : (int32_t)c;",
                "}",
            ]
        src += [_KERNEL.format(ax=ax, args=args) for ax in self.axes]
        sources = dict(_filter_sources(model))
        sources["acnreplay.c"] = "\n".join(src)
        mod = build_module(
            "acn_replay",
            "".join(_DECL.format(ax=ax) for ax in self.axes),
            sources,
            main=["accelnav.c", "acnreplay.c"],
            preamble="#include <stddef.h>\n#include <stdint.h>\n" + "".join(_DECL.format(ax=ax) for ax in self.axes),
        )
        self.ffi, self.lib = mod.ffi, mod.lib
        for ax, nb in zip(self.axes, self.state_bytes, strict=True):
            got = getattr(self.lib, f"acnr_{ax}_size")()
            if got != nb:
                raise ReplayError(f"axis {ax}: the state struct is {got} bytes here, the manifest says {nb}")
        dt = manifest.dtypes["sample"]
        self.row_dtype = dt
        self.offsets = []
        for ax in self.axes:
            off = []
            for st, size in (("r", 8), ("u", 8), ("a", 4), ("e", 8)):  # accelnav_AXIS_out_t's members
                f = dt.fields[f"{ax}.{st}"]
                if f[0].itemsize != size or f[0].byteorder == ">":
                    raise ReplayError(f"{ax}.{st}: the sample row's field is not the read struct's")
                off.append(f[1])
            self.offsets.append(np.array(off, np.int64))

    def run(self, j: int, start, length, init: np.ndarray, code, in1, in2, rows: np.ndarray):
        """Axis ``j`` over stretches (``start``, ``length``: int64 arrays) of the sample arrays ``code`` (uint8),
        ``in1``/``in2`` (uint32); ``init``: (n_stretches, state_bytes) uint8. Writes r, u, a, e of the
        stretches' samples into ``rows`` (the manifest's sample dtype, one per sample; the others untouched);
        returns (final states like ``init``, per stretch the samples whose step verdict disagreed with the
        code)."""
        ax = self.axes[j]
        nb = self.state_bytes[j]
        start = np.ascontiguousarray(start, np.int64)
        length = np.ascontiguousarray(length, np.int64)
        init = np.ascontiguousarray(init, np.uint8).reshape(len(start), nb)
        code = np.ascontiguousarray(code, np.uint8)
        in1 = np.ascontiguousarray(in1, np.uint32)
        in2 = np.ascontiguousarray(in2 if in2 is not None else in1, np.uint32)
        n = len(code)
        if len(start) and int((start + length).max()) > n:
            raise ValueError("a stretch runs past the samples")
        if rows.dtype != self.row_dtype or len(rows) != n or not rows.flags.c_contiguous:
            raise ValueError("rows: one contiguous sample row per sample")
        fin = np.empty_like(init)
        nbad = np.zeros(len(start), np.int64)
        ffi = self.ffi

        def p(a, t):
            return ffi.from_buffer(t, a)

        getattr(self.lib, f"acnr_{ax}")(
            len(start),
            p(start, "int64_t[]"),
            p(length, "int64_t[]"),
            p(init, "uint8_t[]"),
            p(fin, "uint8_t[]"),
            p(code, "uint8_t[]"),
            p(in1, "uint32_t[]"),
            p(in2, "uint32_t[]"),
            ffi.from_buffer("uint8_t[]", rows.view(np.uint8).reshape(-1), require_writable=True),
            rows.dtype.itemsize,
            p(self.offsets[j], "int64_t[]"),
            p(nbad, "int64_t[]"),
        )
        return fin, nbad
