"""The state struct of one axis and its checkpoint image, planned: member types and order, sizes and
offsets, and the checks the image relies on (fixed-size 32- and 64-bit members, no padding), so that
:mod:`codegen.emit_c` only spells them (with their comments).

Sizes and offsets are those of natural alignment: the ARM AAPCS and the x86-64 ABI agree on them for
these types. The gain schedule's row pointer ("seg") has a size that depends on the target; in the
checkpoint image it goes as its index in the table, a uint32.
"""

from __future__ import annotations

from dataclasses import dataclass

from .ranges import DEV

C_SIZES = {"int64_t": 8, "uint64_t": 8, "int32_t": 4, "uint32_t": 4, "int16_t": 2, "uint16_t": 2, "int8_t": 1}
SEG = "seg"  # the member type of the gain schedule's row pointer: const struct T_seg_s *

COV_BLOCK = ("cr", "Pre", "cv", "Pve", "ca", "Pae", "ce")


def state_members(form: str) -> tuple[tuple[str, str], ...]:
    """(C type, name) of the state struct's members, in order: the three int64 first, then the int32 (no
    padding word after a: the covariance state is 64 B, not 72)."""
    m = [("int64_t", "r"), ("int64_t", "v"), ("int64_t", "eb" if form == "gain_schedule" else "e"), ("int32_t", "a")]
    if form == "covariance":
        m += [("int32_t", nm) for nm in COV_BLOCK]
    else:
        # K_r, K_v and K_e's two words in adjacent pairs: one LDRD and one STRD each (ACN_LD2, ACN_ST2)
        m += [("int32_t", "Kr"), ("int32_t", "Kv"), ("uint32_t", "Ke_lo"), ("int32_t", "Ke"), (SEG, "seg")]
        m += [("int32_t", nm) for nm in DEV] + [("uint32_t", "z")]
    return tuple(m + [("uint32_t", "k"), ("uint32_t", "overflow")])


def struct_bytes(fields) -> int | None:
    """sizeof of a struct of these members ((type, name, ...) each) under natural alignment; None when
    a member's size depends on the target (a pointer)."""
    off = align = 0
    for t, *_ in fields:
        n = C_SIZES.get(t)
        if n is None:
            return None
        off = -(-off // n) * n + n
        align = max(align, n)
    return -(-off // align) * align if align else 0


def struct_offsets(fields) -> dict[str, int]:
    """Offset of every member ((type, name, ...) each) under natural alignment (every size known)."""
    out, off = {}, 0
    for t, nm, *_ in fields:
        n = C_SIZES[t]
        off = -(-off // n) * n
        out[nm] = off
        off += n
    return out


@dataclass(frozen=True)
class Layout:
    """One axis' state struct and its checkpoint image (T_save, T_load)."""

    members: tuple[tuple[str, str], ...]  # (C type or SEG, name)
    state_bytes: int | None  # sizeof(T_t); None when it depends on the target (the row pointer)
    ck_members: tuple[tuple[str, str], ...]  # the image's: the row pointer as a uint32 index
    ck_bytes: int
    ck_offsets: dict[str, int]


def layout(form: str) -> Layout:
    """The layout of ``form``'s state, its image checked: 32- and 64-bit members only, none padded."""
    members = state_members(form)
    ck = tuple(("uint32_t", nm) if t == SEG else (t, nm) for t, nm in members)
    if any(C_SIZES[t] not in (4, 8) for t, _ in ck):
        raise ValueError("a checkpoint image takes 32- and 64-bit members only")
    ck_bytes = struct_bytes(ck)
    if ck_bytes is None or ck_bytes != sum(C_SIZES[t] for t, _ in ck):
        raise ValueError(f"{form}: the checkpoint image must be fixed-size members without padding")
    return Layout(members, struct_bytes(members), ck, ck_bytes, struct_offsets(ck))
