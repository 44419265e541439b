"""The host's replay of the firmware's filter, for the compact telemetry mode.

Block frames carry the raw input of every sample (ADC codes or T1/T2 counts)
and a 2-bit code per axis (updated, input refused, no capture, missed by the
board); checkpoint frames carry each axis' state as its checkpoint image
(the generated ``accelnav_AXIS_save``: the covariance form's state struct
bytes; the gain schedule's with its row as an index into the table).
:class:`Replay` compiles the very C the firmware runs (the generated
``accelnav.c`` of the model, :mod:`accelnav.codegen.emit_c`, built with
:mod:`accelnav.native.cbuild` like SIL) together with a small loop that,
for many stretches at once, starts from a state's image (``accelnav_AXIS_load``,
which refuses a gain-schedule row outside the table), steps the filter
through the stretch's inputs exactly as ``firmware/src/app.c`` does (``step``
on the input for codes 0 and 1, ``skip`` for 2 and 3), writes ``r, u, a, e``
of every sample as ``accelnav_AXIS_read`` gives them, and returns the image
of the state at the end of each stretch, for the decoder to hold against the
next checkpoint bit for bit. One C call per axis and decoded batch: no
Python loop over samples.
"""

from __future__ import annotations

import json

import numpy as np

from accelnav.model.load import Model, loads_model

_KERNEL = """
/* Replay of axis {ax}: stretch j starts from the checkpoint image init[j], runs samples
 * start[j] .. start[j] + len[j] - 1 and leaves its final state's image in fin[j];
 * r, u, a, e of sample k (accelnav_{ax}_read) go to rows + k * stride + off[0..3]
 * (little-endian, as the fields of the host's sample rows), nbad[j] counts the
 * samples whose step verdict (input taken or refused) differs from the code sent, plus
 * one for an image the filter refuses (a row outside the table: the decoder refuses such
 * a checkpoint first; here the stretch runs from init and is reported, never past the table). */
void acnr_{ax}(int64_t nseg, const int64_t *start, const int64_t *len, const uint8_t *init, uint8_t *fin,
               const uint8_t *code, const uint32_t *in1, const uint32_t *in2, uint8_t *rows, int64_t stride,
               const int64_t *off, int64_t *nbad)
{{
    int64_t j, k;
    (void)in2;
    for (j = 0; j < nseg; ++j) {{
        accelnav_{ax}_t s;
        int64_t bad = 0;
        if (!accelnav_{ax}_load(&s, init + j * (int64_t)ACCELNAV_{AX}_CK_BYTES)) {{
            accelnav_{ax}_init(&s);
            bad = 1;
        }}
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
        accelnav_{ax}_save(&s, fin + j * (int64_t)ACCELNAV_{AX}_CK_BYTES);
        nbad[j] = bad;
    }}
}}

size_t acnr_{ax}_size(void)
{{
    return ACCELNAV_{AX}_CK_BYTES;
}}
"""

_FILL_DECL = (
    "void acnr_fill(int64_t nblk, const uint8_t *blk, uint8_t *rows, const uint8_t *per_code, uint32_t keep,"
    " uint32_t set, uint32_t first);\n"
)


def _fill_source(manifest) -> str:
    """C of ``acnr_fill``: every field of the sample rows but the states, from the accepted block frames.

    Block b (``manifest.dtypes["block"]`` records, ``n`` slots used) gives rows of the samples
    index + 0 .. index + n - 1, one after another: ``type`` the sample frame's, ``seq`` the index's low
    16 bits, ``flags`` the block's flags masked by ``keep`` with ``set`` added and, on the block's first
    row only, its ``first`` bits too; each axis' ``flags`` from its 2-bit code through ``per_code[4]``;
    the raw inputs from the block's slot; any other field the block's field of the same name. The offsets
    are this manifest's, written in as constants, and every field is read and written byte by byte in
    little-endian order (the host's own byte order does not matter). A sample field no rule covers is a
    ReplayError: the layout changed and this fill no longer knows it."""
    sdt, bdt = manifest.dtypes["sample"], manifest.dtypes["block"]
    axes = list(manifest.axes)
    raw = manifest.raw_fields()
    states = {f"{ax}.{st}" for ax in axes for st in "ruae"}

    def field(dt, name):
        t, off = dt.fields[name][:2]
        base = t.base if t.subdtype else t
        if base.kind != "u" or base.byteorder == ">":
            raise ReplayError(f"{name}: not a little-endian unsigned field, which the row fill expects")
        return off, base.itemsize

    def get(off, size, slot=""):
        parts = [f"(uint32_t)B[{off}{slot}{f' + {i}' if i else ''}] << {8 * i}" for i in range(size)]
        return "(" + " | ".join(parts).replace(" << 0", "") + ")"

    def put(name, expr):
        off, size = field(sdt, name)
        return [f"    acnr_put(r + {off}, {size}, {expr});"]

    body = []
    for name in sdt.names:
        if name in states:
            continue
        if name == "type":
            body += put(name, str(int(manifest.frames["sample"]["type"])))
        elif name == "seq":
            body += put(name, "ix & 0xFFFFu")
        elif name == "index":
            body += put(name, "ix")
        elif name == "flags":
            body += put(name, "fl | (s == 0 ? bf & first : 0u)")
        elif name.split(".", 1)[0] in axes and name.endswith(".flags"):
            j = axes.index(name.split(".", 1)[0])
            body += put(name, f"per_code[(af >> {2 * j}) & 3u]")
        elif name.split(".", 1)[-1] in raw:
            off, size = field(bdt, name)
            body += put(name, get(off, size, f" + s * {size}"))
        elif name in bdt.names and not bdt.fields[name][0].subdtype:
            body += put(name, get(*field(bdt, name)))
        else:
            raise ReplayError(f"the row fill has no rule for the sample field {name!r}")
    o_idx, o_fl, o_n, o_af = (field(bdt, k) for k in ("index", "flags", "n", "aflags"))
    return "\n".join(
        [
            "static void acnr_put(uint8_t *p, int size, uint32_t v)",
            "{",
            "    int i;",
            "    for (i = 0; i < size; ++i) p[i] = (uint8_t)(v >> (8 * i));",
            "}",
            "",
            "void acnr_fill(int64_t nblk, const uint8_t *blk, uint8_t *rows, const uint8_t *per_code, uint32_t keep,",
            "               uint32_t set, uint32_t first)",
            "{",
            "    int64_t b;",
            "    uint32_t s;",
            "    for (b = 0; b < nblk; ++b) {",
            f"        const uint8_t *B = blk + b * {bdt.itemsize};",
            f"        uint32_t n = {get(*o_n)}, i0 = {get(*o_idx)}, bf = {get(*o_fl)}, fl = (bf & keep) | set;",
            "        for (s = 0; s < n; ++s) {",
            f"            uint8_t *r = rows + {sdt.itemsize} * s;",
            f"            uint32_t ix = i0 + s, af = B[{o_af[0]} + s];",
            *["        " + line for line in body],
            "        }",
            f"        rows += {sdt.itemsize} * n;",
            "    }",
            "}",
            "",
        ]
    )


_DECL = (
    "void acnr_{ax}(int64_t nseg, const int64_t *start, const int64_t *len, const uint8_t *init, uint8_t *fin,"
    " const uint8_t *code, const uint32_t *in1, const uint32_t *in2, uint8_t *rows, int64_t stride,"
    " const int64_t *off, int64_t *nbad);\n"
    "size_t acnr_{ax}_size(void);\n"
)


class ReplayError(ValueError):
    """The replay cannot be built for this manifest and model; ``str()`` is one line."""


class Replay:
    """The firmware's filter for the axes of ``manifest``, from ``model`` (a Model or its TOML text).

    A log is data from someone else: its manifest and model text are both untrusted. Only C generated
    from a model that passed the loader is compiled, and the manifest must be the very one that model
    generates, so nothing of the log but the loader-checked model shapes the C built here."""

    def __init__(self, manifest, model: Model | str):
        from accelnav.codegen.generated import generated_files
        from accelnav.native.cbuild import build_module

        if isinstance(model, str):
            model = loads_model(model, source="the model text of the recording")
        if model.sha256 != manifest.model_sha256:
            raise ReplayError(
                f"the model text (sha256 {model.sha256[:12]}) is not the firmware's model "
                f"({manifest.model_sha256[:12]}): no replay"
            )
        files = generated_files(model)
        if json.loads(files["acnframe.json"]) != manifest.data:
            raise ReplayError("the frame manifest is not the one its model generates: no replay")
        self.axes = [a.name for a in model.axes]  # names the loader checked; the manifest's are the same
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
        src += [_KERNEL.format(ax=ax, AX=ax.upper(), args=args) for ax in self.axes]
        src.append(_fill_source(manifest))
        sources = {k: v for k, v in files.items() if k in ("accelnav.h", "accelnav.c")}
        sources["acnreplay.c"] = "\n".join(src)
        mod = build_module(
            "acn_replay",
            "".join(_DECL.format(ax=ax) for ax in self.axes) + _FILL_DECL,
            sources,
            main=["accelnav.c", "acnreplay.c"],
            preamble="#include <stddef.h>\n#include <stdint.h>\n"
            + "".join(_DECL.format(ax=ax) for ax in self.axes)
            + _FILL_DECL,
        )
        self.ffi, self.lib = mod.ffi, mod.lib
        for ax, nb in zip(self.axes, self.state_bytes, strict=True):
            got = getattr(self.lib, f"acnr_{ax}_size")()
            if got != nb:
                raise ReplayError(f"axis {ax}: the checkpoint image is {got} bytes here, the manifest says {nb}")
        dt = manifest.dtypes["sample"]
        self.row_dtype = dt
        self.block_dtype = manifest.dtypes["block"]
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

    def fill(self, blocks: np.ndarray, rows: np.ndarray, per_code, keep: int, set_: int, first: int) -> None:
        """Every field but the states of ``rows`` (one per sample of the ``blocks``, in order): see
        :func:`_fill_source` for the rules and what ``per_code``, ``keep``, ``set_``, ``first`` mean."""
        blocks = np.ascontiguousarray(blocks)
        if blocks.dtype != self.block_dtype:
            raise ValueError("blocks: the manifest's block records")
        ns = blocks["n"].astype(np.int64)
        if len(ns) and (ns.min() < 0 or ns.max() > self.block_dtype["aflags"].shape[0]):
            raise ValueError("blocks: a block with more samples than slots")
        n = int(ns.sum())
        if rows.dtype != self.row_dtype or len(rows) != n or not rows.flags.c_contiguous:
            raise ValueError("rows: one contiguous sample row per sample of the blocks")
        per_code = np.ascontiguousarray(per_code, np.uint8)
        if per_code.shape != (4,):
            raise ValueError("per_code: four axis flags")
        ffi = self.ffi
        self.lib.acnr_fill(
            len(blocks),
            ffi.from_buffer("uint8_t[]", blocks.view(np.uint8).reshape(-1)),
            ffi.from_buffer("uint8_t[]", rows.view(np.uint8).reshape(-1), require_writable=True),
            ffi.from_buffer("uint8_t[]", per_code),
            keep,
            set_,
            first,
        )
