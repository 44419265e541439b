"""Does the generated filter fit a named part? ``accelnav codegen MODEL --report --target PART``.

The parts (memories, usual clock, compiler, flags) come from the firmware's own table,
``firmware/parts.mk``, which firmware.mk includes for its builds and its ATmega328P size check: the
report and the build read the same numbers. Sizes are measured, never estimated: the generated
filter is compiled with that part's compiler and the firmware's flags, and its sections summed
(``size -A``). A missing toolchain is said in one line and gives no figure.
"""

from __future__ import annotations

import functools
import re
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from accelnav.native.cbuild import STRICT_WARN
from accelnav.resources import firmware_dir

FORMS = ("covariance", "gain_schedule")


class TargetError(ValueError):
    """An unknown part, or the part's compiler refusing the generated C; ``str()`` is one line (the CLI
    prints it as a user error: the generator stands below accelnav.errors' CLI-facing type)."""


_FIELD = re.compile(r"^PART_([A-Z]+)_(\w+)\s*:=[ \t]*(.*?)\s*$", re.M)


@dataclass(frozen=True)
class Part:
    key: str  # the firmware's BOARD name
    name: str
    aliases: tuple[str, ...]
    flash: int  # bytes, datasheet
    ram: int
    mhz: float  # the usual clock
    cc: str
    size: str
    cflags: tuple[str, ...]  # the part's flags; FW_WARN comes first, as in firmware.mk


@functools.cache
def _table(path: Path) -> dict[str, Part]:
    text = path.read_text()
    fields: dict[str, dict[str, str]] = {}
    for field, key, value in _FIELD.findall(text):
        fields.setdefault(key, {})[field] = value
    parts = {
        key: Part(
            key,
            f["NAME"],
            tuple(f["ALIASES"].split()),
            int(f["FLASH"]),
            int(f["RAM"]),
            float(f["MHZ"]),
            f["CC"],
            f["SIZE"],
            tuple(f["CFLAGS"].split()),
        )  # fmt: skip
        for key, f in fields.items()
    }
    return parts


def parts() -> dict[str, Part]:
    """The part table of firmware/parts.mk, by BOARD name."""
    return _table(firmware_dir() / "parts.mk")


def warn_flags() -> tuple[str, ...]:
    """FW_WARN: the flags every firmware source is compiled with."""
    return STRICT_WARN


def known() -> str:
    return ", ".join(p.key + "".join(f"/{a}" for a in p.aliases) for p in parts().values())


def part(name: str) -> Part:
    """The part named by its BOARD name or an alias (case-insensitive), or TargetError listing them."""
    low = name.lower()
    for p in parts().values():
        if low == p.key or low in p.aliases:
            return p
    raise TargetError(f"--target: unknown part {ascii(name[:40])}; known: {known()}")


def missing_tools(p: Part) -> str | None:
    """One line naming the part's missing compiler or size tool, or None."""
    gone = [t for t in (p.cc, p.size) if shutil.which(t) is None]
    return f"{', '.join(gone)} not found: no figure for the {p.key}" if gone else None


@dataclass(frozen=True)
class Sized:
    """One form compiled for a part: flash (code, constants, initialised data) and static RAM of the
    filter object, and each axis' state struct (RAM the caller allocates)."""

    form: str
    flash: int
    static_ram: int
    states: dict[str, int]

    @property
    def ram(self) -> int:
        return self.static_ram + sum(self.states.values())


def measure(p: Part, files: dict[str, str], prefix: str, form: str) -> Sized:
    """Compile ``PREFIX.c`` for part ``p`` with the firmware's flags and sum its sections; the state
    structs are sized by the same compiler (one object of each, in its own .bss section)."""
    axes = re.findall(rf"^void ({re.escape(prefix)}_(\w+))_init\(\1_t \*s\);", files[f"{prefix}.h"], re.M)
    states = f'#include "{prefix}.h"\n' + "".join(f"{t}_t acn_state_{a};\n" for t, a in axes)
    avr = p.cc.startswith("avr")  # avr-gcc copies .rodata into RAM at start (PROGMEM tables stay in flash)
    with tempfile.TemporaryDirectory(prefix="accelnav-size-") as tmp:
        d = Path(tmp)
        for name, text in files.items():
            (d / name).write_text(text)
        (d / "acn_states.c").write_text(states)
        sec = {}
        for src, extra in ((f"{prefix}.c", ()), ("acn_states.c", ("-fno-common",))):
            obj = d / (src[:-2] + ".o")
            done = subprocess.run([p.cc, *warn_flags(), *p.cflags, *extra, "-c", str(d / src), "-o", str(obj)],
                                  capture_output=True, text=True)  # fmt: skip
            if done.returncode:
                raise TargetError(f"{p.cc}: " + (done.stderr.strip().splitlines() or ["failed"])[0])
            out = subprocess.run([p.size, "-A", str(obj)], capture_output=True, text=True, check=True).stdout
            sec[src] = re.findall(r"^(\.\S+)\s+(\d+)", out, re.M)
    flash = ram = 0
    for name, n in sec[f"{prefix}.c"]:
        n = int(n)
        m = re.match(r"\.s?(text|progmem|rodata|data|bss)\b", name)  # .srodata etc.: RISC-V's small sections
        kind = m[1] if m else None
        if kind in ("text", "progmem"):
            flash += n
        elif kind == "rodata":
            flash += n
            ram += n if avr else 0
        elif kind == "data":
            flash += n
            ram += n
        elif kind == "bss":
            ram += n
    st = {a: 0 for _, a in axes}
    for name, n in sec["acn_states.c"]:
        m = re.fullmatch(r"\.s?bss\.acn_state_(\w+)", name)
        if m:
            st[m[1]] = int(n)
    return Sized(form, flash, ram, st)


@dataclass(frozen=True)
class Fit:
    part: Part
    form: str  # the form asked for
    sized: dict[str, Sized]  # per form measured; empty without the toolchain
    missing: str | None  # the one line that says why there is no figure

    def fits(self, form: str) -> bool:
        s = self.sized[form]
        return s.flash <= self.part.flash and s.ram <= self.part.ram

    def refusal(self) -> str | None:
        """One line when the form asked for does not fit, naming the form that does; None when it
        fits or could not be measured."""
        if self.missing or self.form not in self.sized or self.fits(self.form):
            return None
        s, p = self.sized[self.form], self.part
        need = []
        if s.flash > p.flash:
            need.append(f"{s.flash} B flash of {p.flash}")
        if s.ram > p.ram:
            need.append(f"{s.ram} B RAM of {p.ram}")
        other = [self.sized[f] for f in self.sized if f != self.form and self.fits(f)]
        alt = "no form fits"
        if other:
            alt = f"the {other[0].form.replace('_', ' ')} form fits: {other[0].flash} B flash, {other[0].ram} B RAM"
        return f"{self.form} form on the {p.key} does not fit: needs {' and '.join(need)}; {alt}"

    def lines(self) -> list[str]:
        p = self.part
        out = [
            f"target {p.key}: {p.name}, {p.flash} B flash, {p.ram} B RAM (datasheet), {p.mhz:g} MHz; "
            f"{p.cc} {' '.join(p.cflags)}"
        ]
        if self.missing:
            return out + [f"  {self.missing}"]
        head = f"  {'form':<14} {'flash B':>8} {'RAM B':>6}  {'verdict':<13}"
        out.append(head + " the filter alone: static RAM + each axis' state")
        for form, s in self.sized.items():
            axes = " + ".join(f"{a} {n}" for a, n in s.states.items())
            verdict = "fits" if self.fits(form) else "does not fit"
            mark = " (asked for)" if form == self.form else ""
            out.append(f"  {form:<14} {s.flash:8d} {s.ram:6d}  {verdict:<13} {s.static_ram} + {axes}{mark}")
        verdict = self.refusal() or f"the {self.form} form fits the {p.key}"
        out.append(f"  {verdict} (the filter object alone: libgcc's helpers and the application need their own share)")
        return out


def fit(p: Part, model, form: str, arith: str, files: dict[str, str], prefix: str) -> Fit:
    """Measure the form asked for (``files``, already emitted) and, fixed point, the other form too."""
    from .emit_c import emit

    missing = missing_tools(p)
    if missing:
        return Fit(p, form, {}, missing)
    todo = {form: files}
    if arith == "fixed":
        for other in FORMS:
            if other != form:
                todo[other] = emit(model, form=other, arith=arith, prefix=prefix)
    with ThreadPoolExecutor(max_workers=2) as pool:
        sized = {s.form: s for s in pool.map(lambda kv: measure(p, kv[1], prefix, kv[0]), todo.items())}
    return Fit(p, form, sized, None)
