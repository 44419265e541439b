"""The float32 variant of the generated filter (MCUs with an FPU; the soft-float baseline of the bench).

Same API as the fixed-point C (init, convert, step, skip, update, read), same
structure (the seven-entry block of P, the gain from it, one division per
update), in float32 and natural units. It is the covariance form whatever the
model's form: a float32 gain table would only be the fixed-point schedule in
a wider word.
"""

from __future__ import annotations

from accelnav.model.design import AnalogConversion, axis_design, input_conversion
from accelnav.model.load import G0, Model

from .package import package


def _f(x: float) -> str:
    return f"{float(x):.9e}f"


def _axis(model: Model, i: int, prefix: str) -> tuple[list[str], list[str], dict]:
    d = axis_design(model, i)
    conv = input_conversion(model, i)
    ax = d.axis.name
    T = f"{prefix}_{ax}"
    Ts = d.Ts
    fields = ["r", "u", "a", "e", "Pra", "Pua", "Paa", "Pre", "Pue", "Pae", "Pee"]
    struct = ["typedef struct {"] + [f"    float {f};" for f in fields]
    struct += ["    uint32_t k;", "    uint32_t overflow; /* always 0: float32 does not saturate */", f"}} {T}_t;"]
    out_struct = ["typedef struct {", "    float r;", "    float u;", "    float a;", "    float e;", f"}} {T}_out_t;"]
    if isinstance(conv, AnalogConversion):
        params, args = "int32_t code", "code"
        conv_body = [
            f"    if (code <= 0 || code >= {conv.full_code}) {{",
            "        return false;",
            "    }",
            f"    *z = (float)code * {_f(conv.scale)} + {_f(conv.offset)};",
            "    return true;",
        ]
    else:
        nom = conv.t2_nominal
        params, args = "int32_t t1, int32_t t2", "t1, t2"
        conv_body = [
            f"    if (t2 <= 0 || t1 <= 0 || t1 >= t2 || (int64_t)4 * t2 - {4 * nom} > {nom} ||"
            f" (int64_t)4 * t2 - {4 * nom} < -{nom}) {{",
            "        return false;",
            "    }",
            f"    *z = ((float)t1 / (float)t2 - {_f(conv.zero_g_duty)}) * {_f(G0 / conv.duty_per_g)};",
            "    return true;",
        ]
    protos = [
        f"void {T}_init({T}_t *s);",
        f"bool {T}_convert({params}, float *z);",
        f"bool {T}_step({T}_t *s, {params});",
        f"void {T}_skip({T}_t *s);",
        f"void {T}_update({T}_t *s, float z);",
        f"void {T}_read(const {T}_t *s, {T}_out_t *o);",
    ]
    P0 = d.P0
    init = [f"void {T}_init({T}_t *s)", "{"]
    for f, v in zip(
        fields,
        [d.x0[0], d.x0[1], d.x0[2], d.x0[3], P0[0, 2], P0[1, 2], P0[2, 2], P0[0, 3], P0[1, 3], P0[2, 3], P0[3, 3]],
        strict=True,
    ):
        init.append(f"    s->{f} = {_f(v)};")
    init += ["    s->k = 0;", "    s->overflow = 0;", "}", ""]
    Q = d.Q
    phi = d.phi
    src = init + [f"bool {T}_convert({params}, float *z)", "{"] + conv_body + ["}", ""]
    src += [
        f"static void {T}_predict({T}_t *s)",
        "{",
        "    /* x = F x + b */",
        f"    s->r += {_f(Ts)} * s->u + {_f(Ts * Ts / 2)} * s->a;",
        f"    s->u += {_f(Ts)} * s->a;",
        f"    s->e = {_f(phi)} * s->e + {_f(d.b[3])};",
        "    /* P = F P F' + Q, the block the gain needs (old values on the right) */",
        f"    s->Pra = s->Pra + {_f(Ts)} * s->Pua + {_f(Ts * Ts / 2)} * s->Paa + {_f(Q[0, 2])};",
        f"    s->Pre = {_f(phi)} * (s->Pre + {_f(Ts)} * s->Pue + {_f(Ts * Ts / 2)} * s->Pae);",
        f"    s->Pua = s->Pua + {_f(Ts)} * s->Paa + {_f(Q[1, 2])};",
        f"    s->Pue = {_f(phi)} * (s->Pue + {_f(Ts)} * s->Pae);",
        f"    s->Paa = s->Paa + {_f(Q[2, 2])};",
        f"    s->Pae = {_f(phi)} * s->Pae;",
        f"    s->Pee = {_f(phi * phi)} * s->Pee + {_f(Q[3, 3])};",
        "}",
        "",
        f"void {T}_update({T}_t *s, float z)",
        "{",
        "    float cr, cu, ca, ce, S, iS, Kr, Ku, Ka, Ke, y;",
        "    if (s->k > 0) {",
        f"        {T}_predict(s);",
        "    }",
        "    /* c = P H', S = H P H' + R, K = c / S */",
        "    cr = s->Pra + s->Pre;",
        "    cu = s->Pua + s->Pue;",
        "    ca = s->Paa + s->Pae;",
        "    ce = s->Pae + s->Pee;",
        f"    S = ca + ce + {_f(d.R)};",
        "    iS = 1.0f / S;",
        "    Kr = cr * iS;",
        "    Ku = cu * iS;",
        "    Ka = ca * iS;",
        "    Ke = ce * iS;",
        "    /* y = z - H x;  x = x + K y */",
        "    y = z - s->a - s->e;",
        "    s->r += Kr * y;",
        "    s->u += Ku * y;",
        "    s->a += Ka * y;",
        "    s->e += Ke * y;",
        "    /* P = P - K c' */",
        "    s->Pra -= Kr * ca;",
        "    s->Pua -= Ku * ca;",
        "    s->Paa -= Ka * ca;",
        "    s->Pre -= Kr * ce;",
        "    s->Pue -= Ku * ce;",
        "    s->Pae -= Ka * ce;",
        "    s->Pee -= Ke * ce;",
        "    ++s->k;",
        "}",
        "",
        f"void {T}_skip({T}_t *s)",
        "{",
        "    if (s->k > 0) {",
        f"        {T}_predict(s);",
        "    }",
        "    ++s->k;",
        "}",
        "",
        f"bool {T}_step({T}_t *s, {params})",
        "{",
        "    float z;",
        f"    if (!{T}_convert({args}, &z)) {{",
        f"        {T}_skip(s);",
        "        return false;",
        "    }",
        f"    {T}_update(s, z);",
        "    return true;",
        "}",
        "",
        f"void {T}_read(const {T}_t *s, {T}_out_t *o)",
        "{",
        "    o->r = s->r;",
        "    o->u = s->u;",
        "    o->a = s->a;",
        "    o->e = s->e;",
        "}",
        "",
    ]
    header = struct + [""] + out_struct + [""] + protos
    return header, src, {"axis": ax, "form": "covariance", "variables": {}}


def emit_f32(model: Model, *, form: str, prefix: str) -> dict[str, str]:
    H, S, MAN = [], [], []
    for i in range(len(model.axes)):
        h, s, man = _axis(model, i, prefix)
        H += h + [""]
        S += s
        MAN.append(man)
    return package(
        model,
        prefix,
        what_h="float32 covariance filter, one set per axis",
        what_c=f"float32 covariance filter (requested form: {form}). No heap, no libc.",
        declarations=H,
        source_includes="",
        source_prelude="\n",
        body=S,
        manifest={"arith": "float32", "form": "covariance", "axes": MAN},
    )
