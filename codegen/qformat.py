"""Fixed-point formats and the one quantizer.

A value v is held as the integer q = v * 2**frac in a signed word of ``word``
bits; ``Q{int}.{frac}`` names it the CMSIS way (int + frac = word - 1, sign
bit not counted; int may be negative for small values, e.g. Q-8.39).

:func:`quantize` is the only place a real number becomes an integer: it
rounds to nearest (ties toward +inf, the same as the C idiom
``(x + (1 << (s - 1))) >> s``) and then saturates to the word. Emitted
constants and test data both go through it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class QFormat:
    word: int  # 32 or 64
    frac: int  # fractional bits (may exceed word - 1 for tiny values)

    @property
    def int_bits(self) -> int:
        return self.word - 1 - self.frac

    @property
    def lsb(self) -> float:
        return 2.0**-self.frac

    @property
    def qmax(self) -> int:
        return 2 ** (self.word - 1) - 1

    @property
    def qmin(self) -> int:
        return -(2 ** (self.word - 1))

    @property
    def max_value(self) -> float:
        return self.qmax * self.lsb

    @property
    def ctype(self) -> str:
        return f"int{self.word}_t"

    @property
    def name(self) -> str:
        return f"Q{self.int_bits}.{self.frac}"

    def __str__(self) -> str:
        return self.name


def bits_for(bound: float) -> int:
    """Integer bits (sign excluded) needed to hold every |v| <= bound: 2**ib > bound."""
    if not bound > 0 or not math.isfinite(bound):
        raise ValueError(f"bound must be finite and > 0, got {bound!r}")
    m, e = math.frexp(bound)  # bound = m * 2**e, 0.5 <= m < 1, so 2**e > bound
    return e


def fit(bound: float, word: int) -> QFormat:
    """The format of ``word`` bits with the most fractional bits that holds +-bound."""
    return QFormat(word, word - 1 - bits_for(bound))


def quantize(value, fmt: QFormat):
    """Round to nearest (ties up), then saturate to ``fmt``; scalar -> int, array -> int64 array (word <= 64)."""
    if np.ndim(value) == 0:
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"cannot quantize {v!r}")
        try:
            q = math.floor(math.ldexp(v, fmt.frac) + 0.5)
        except OverflowError:  # far beyond any word: saturate
            q = fmt.qmax if v > 0 else fmt.qmin
        return int(min(max(q, fmt.qmin), fmt.qmax))
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError("cannot quantize non-finite values")
    with np.errstate(over="ignore"):
        scaled = np.floor(np.ldexp(arr, fmt.frac) + 0.5)
    # clip in float first: values beyond int64 saturate instead of wrapping
    scaled = np.clip(scaled, float(fmt.qmin), float(fmt.qmax))
    top = scaled >= 2.0**63  # float64 cannot hold 2**63 - 1: set those in integers
    out = np.where(top, 0.0, scaled).astype(np.int64)
    out[top] = fmt.qmax
    return out


def dequantize(q, fmt: QFormat):
    """The real value of integer(s) q in ``fmt``."""
    if np.ndim(q) == 0:
        return math.ldexp(float(int(q)), -fmt.frac)
    return np.ldexp(np.asarray(q, dtype=np.float64), -fmt.frac)


def const_format(value: float, word: int = 32) -> QFormat:
    """Per-constant scaling: the format that gives ``value`` the full word (mantissa + its own shift)."""
    if value == 0:
        return QFormat(word, word - 2)
    return fit(abs(value) * (1 + 2.0 ** -(word - 2)), word)


GUARD_BITS = 16  # bits below the target's LSB at which a sum of three or more fine terms is formed
GUARD_BITS_2 = 32  # ... and a sum of one or two: at 32 the rounding is the high word, no shift


def guard_bits(fine_fracs: list[int], ft: int) -> int:
    """Guard bits g of a sum rounded once to Q.ft (codegen.emit_c._acc) whose finer terms have
    ``fine_fracs`` fractional bits: the most that needs no left shift of any of them, at most
    GUARD_BITS_2 for one or two such terms and GUARD_BITS for more."""
    return min(GUARD_BITS_2 if len(fine_fracs) <= 2 else GUARD_BITS, *(fr - ft for fr in fine_fracs))


def acc_bound(ft: int, terms: list[tuple[int, int]], dither: bool = False) -> int:
    """A bound, in LSB of Q.ft, on |sum| as codegen.emit_c._acc forms it from terms given as (bound on
    |term| in its own LSB, its fractional bits): the terms in Q.ft exactly, the finer ones each floored
    to Q.(ft + g) (one more LSB of that each), the rounding offset (half an LSB, or with ``dither``
    up to one), then the shift by g (one more LSB for its floor)."""
    exact = sum(m for m, fr in terms if fr == ft)
    fine = [(m, fr) for m, fr in terms if fr != ft]
    if not fine:
        return exact
    g = guard_bits([fr for _, fr in fine], ft)
    tot = sum((m >> (fr - ft - g)) + 1 for m, fr in fine) + ((1 << g) - 1 if dither else 1 << (g - 1))
    return exact + (tot >> g) + 1
