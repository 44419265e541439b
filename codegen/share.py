"""One copy of the covariance step for every axis, its per-axis numbers in tables (AVR).

The axes of a model run the same step and differ in numbers only: constants, and the shifts their
formats need. :func:`merge` reads each axis' step functions (written with every shift explicit, even
by zero, so that their texts line up) token by token; where the axes agree the text stays, where they
differ in a number the number becomes a field of a per-axis table. A number that differs is taken into
a field of its own C type, so every expression computes exactly what the axis' own copy does:

* ``INT32_C(v)``, ``INT64_C(v)``, ``UINT32_C(v)`` (and ``INT32_MIN``, ``INT64_MIN``): int32_t,
  int64_t, uint32_t, the types those macros give;
* a plain decimal 0..255 (shift counts): uint8_t, which promotes to int as the literal is.

Anything else that differs (a name, an operator, a suffixed literal) means the axes do not share a
step: :func:`merge` says which and where, and the emitter keeps one step per axis. Pure: texts in,
texts out.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_LIT = r"U?INT(?:32|64)_C\(-?\d+\)|INT(?:32|64)_MIN|\d+[uUlL]*"
_TOKEN = re.compile(rf"{_LIT}|[A-Za-z_]\w*|->|>>=|<<=|>>|<<|\+\+|--|[-+*/%&|^<>=!]=|&&|\|\||\S")
_COMMENT = re.compile(r"/\*.*?\*/", re.S)

# field types by literal kind, and their reads from the table (ACN_ROM: flash on AVR)
_KIND = {
    "INT32_C": ("int32_t", "ACN_ROM_I32"),
    "INT32_MIN": ("int32_t", "ACN_ROM_I32"),
    "INT64_C": ("int64_t", "ACN_ROM_I64"),
    "INT64_MIN": ("int64_t", "ACN_ROM_I64"),
    "UINT32_C": ("uint32_t", "ACN_ROM_U32"),
    "": ("uint8_t", "ACN_ROM_U8"),
}
_SAME = {"INT32_MIN": "INT32_C", "INT64_MIN": "INT64_C"}
_ORDER = ("int64_t", "int32_t", "uint32_t", "uint8_t")  # the table's fields, widest first: no padding


def _kind(tok: str) -> str | None:
    """The literal kind of a token (a key of _KIND), None if it is no literal a field can take."""
    m = re.fullmatch(r"(U?INT(?:32|64)_C)\(-?\d+\)|(INT(?:32|64)_MIN)|(\d+)", tok)
    if not m:
        return None
    if m[3] is not None:
        return "" if int(m[3]) <= 255 else None
    return m[1] or m[2]


@dataclass(frozen=True)
class Shared:
    """The shared text (its table reads through ``ACN_K(type, field)``), the table's C members, and each
    axis' initialiser (in the members' order)."""

    text: str
    members: list[str]
    inits: list[list[str]]


def tokens(text: str) -> list[str]:
    """The C tokens of ``text``, comments dropped."""
    return _TOKEN.findall(_COMMENT.sub(" ", text))


def merge(texts: list[str]) -> Shared | str:
    """One text for all ``texts`` (each axis' step, its own names already made common), or why not: a
    one-line reason naming the first place the axes differ in more than a number."""
    toks = [tokens(t) for t in texts]
    if len({len(t) for t in toks}) != 1:
        n = min(len(t) for t in toks)
        at = next((i for i in range(n) if len({t[i] for t in toks}) > 1), n)
        return f"their steps differ in shape near '{' '.join(toks[0][max(0, at - 6) : at + 3])}'"
    fields: dict[tuple[str, ...], str] = {}  # the axes' values at a place -> its field (equal values share)
    kinds: dict[str, str] = {}
    out = []
    for i, col in enumerate(zip(*toks, strict=True)):
        if len(set(col)) == 1:
            out.append(col[0])
            continue
        ks = {_SAME.get(_kind(t), _kind(t)) for t in col}  # INT32_MIN beside INT32_C(v): both int32_t
        if len(ks) != 1 or None in ks:
            ctx = " ".join(toks[0][max(0, i - 6) : i + 3])
            return f"their steps differ in more than a number: {' / '.join(col)} near '{ctx}'"
        k = ks.pop()
        name = fields.setdefault(col, f"f{len(fields)}")
        kinds[name] = k
        read = _KIND[k][1]
        out.append(f"{read}(&acn_k->{name})")
    # the table's members widest first; each axis' values in the same order
    order = sorted(fields.items(), key=lambda kv: (_ORDER.index(_KIND[kinds[kv[1]]][0]), int(kv[1][1:])))
    members = [f"{_KIND[kinds[n]][0]} {n};" for _, n in order]
    inits = [[col[a] for col, _ in order] for a in range(len(texts))]
    if not members:  # the axes' numbers all alike: C has no empty struct
        members, inits = ["uint8_t none; /* the axes' steps are the same */"], [["0"] for _ in texts]
    return Shared(_join(out).replace(" >> 0)", ")"), members, inits)  # shifts by zero in every axis: none


def _join(toks: list[str]) -> str:
    """Tokens back to C: a statement a line, indented by its braces; one space between tokens but none
    inside parentheses' edges, before ';' ',' or a call's '(', or around '->'."""
    out, depth, braces = [], 0, 0
    for t in toks:
        if t == "}":
            braces -= 1
        if out and out[-1] == "\n":
            out.append("    " * braces)
        elif out and t not in (";", ",", ")", "->") and not out[-1].endswith(("(", "->", " ")):
            if not (t == "(" and re.fullmatch(r"[A-Za-z_]\w*", out[-1]) and out[-1] not in ("if", "return")):
                out.append(" ")
        out.append(t)
        depth += (t == "(") - (t == ")")
        if t == "{":
            braces += 1
        if depth == 0 and t in ("{", "}", ";"):
            out.append("\n")
    return "".join(out)
