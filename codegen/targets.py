"""Does the generated filter fit a named part? ``accelnav codegen MODEL --report --target PART``.

The parts (memories, usual clock, compiler, flags) come from the firmware's own table,
``firmware/parts.mk``, which firmware.mk includes for its builds and its ATmega328P size check: the
report and the build read the same numbers. Sizes are measured, never estimated: the verdict reads the
part's firmware image linked as ``make firmware BOARD=PART`` links it (firmware.mk: the part's compiler,
flags, libc and --gc-sections), so code the linker drops is not counted and the application, libc and
libgcc's helpers are; :func:`measure` sizes the filter's object alone (each axis' state struct, the
per-architecture bench). A missing toolchain is said in one line and gives no figure.
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
    stack: int = 0  # bytes of RAM kept for the stack (measured in simavr); 0: not known, not counted


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
            int(f.get("STACK", "0")),
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
    """One line naming the part's missing compiler, size tool or make (the image's link), or None."""
    gone = [t for t in (p.cc, p.size, "make") if shutil.which(t) is None]
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
class Linked:
    """The part's firmware image of one form, linked: flash (text + data) and static RAM (data + bss:
    every axis' state, the telemetry buffers, libc's), as GNU size counts them."""

    form: str
    flash: int
    ram: int


LINK_TIMEOUT_S = 300


def image_size(p: Part, elf: Path) -> tuple[int, int]:
    """(flash, static RAM) of a linked image: text + data and data + bss of ``size`` (Berkeley)."""
    out = subprocess.run([p.size, str(elf)], capture_output=True, text=True, check=True).stdout
    text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
    return text + data, data + bss


def link(p: Part, files: dict[str, str], form: str) -> Linked:
    """The firmware image of part ``p`` around the generated ``files`` (the filter and frame code of prefix
    accelnav), linked by firmware.mk in a private folder, and sized. The ATmega328P's own size check is
    lifted (its limits raised) so that an image too big still gives its figures."""
    fw = firmware_dir()
    with tempfile.TemporaryDirectory(prefix="accelnav-link-") as tmp:
        gen, out = Path(tmp, "gen"), Path(tmp, "out")
        gen.mkdir()
        for name, text in files.items():
            (gen / name).write_text(text)
        cmd = ["make", "--no-print-directory", "-f", str(fw / "firmware.mk"), "firmware", f"BOARD={p.key}",
               f"FW_DIR={fw}", f"FW_GEN={gen}", f"FW_OUT={out}", "FW_PREGEN=1", "AVR_FLASH=16777216",
               "AVR_RAM=16777216"]  # fmt: skip
        try:
            done = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=LINK_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise TargetError(f"the {p.key} image ({form} form) did not link within {LINK_TIMEOUT_S} s") from None
        if done.returncode:
            why = [ln for ln in done.stderr.splitlines() if "error" in ln.lower()] or done.stderr.splitlines()
            raise TargetError(f"linking the {p.key} image ({form} form): " + (why or ["failed"])[0][:300])
        elf = out / ("accelnav_fw" if p.key == "host" else "accelnav_fw.elf")
        flash, ram = image_size(p, elf)
    return Linked(form, flash, ram)


@dataclass(frozen=True)
class Fit:
    part: Part
    form: str  # the form asked for
    sized: dict[str, Linked]  # per form, its image linked; empty without the toolchain
    missing: str | None  # the one line that says why there is no figure
    states: dict[str, int] | None = None  # each axis' state struct of the form asked for

    def fits(self, form: str) -> bool:
        s = self.sized[form]
        return s.flash <= self.part.flash and s.ram + self.part.stack <= self.part.ram

    def refusal(self) -> str | None:
        """One line when the form asked for does not fit, naming the form that does; None when it
        fits or could not be measured."""
        if self.missing or self.form not in self.sized or self.fits(self.form):
            return None
        s, p = self.sized[self.form], self.part
        need = []
        if s.flash > p.flash:
            need.append(f"{s.flash} B flash of {p.flash}")
        if s.ram + p.stack > p.ram:
            need.append(f"{s.ram} B RAM + {p.stack} B stack of {p.ram}" if p.stack else f"{s.ram} B RAM of {p.ram}")
        other = [self.sized[f] for f in self.sized if f != self.form and self.fits(f)]
        alt = "no form fits"
        if other:
            alt = f"the {other[0].form.replace('_', ' ')} form fits: {other[0].flash} B flash, {other[0].ram} B RAM"
        image = "linked image" if s.flash > p.flash else f"linked image; its {s.flash} B flash of {p.flash} would fit"
        return f"{self.form} form on the {p.key} does not fit: needs {' and '.join(need)} ({image}); {alt}"

    def lines(self) -> list[str]:
        p = self.part
        out = [
            f"target {p.key}: {p.name}, {p.flash} B flash, {p.ram} B RAM (datasheet), {p.mhz:g} MHz; "
            f"{p.cc} {' '.join(p.cflags)}"
        ]
        if self.missing:
            return out + [f"  {self.missing}"]
        stack = f" + {p.stack} B stack (measured)" if p.stack else " (stack not counted)"
        out.append(f"  {'form':<14} {'flash B':>8} {'RAM B':>6}  verdict: the firmware image linked (make firmware "
                   f"BOARD={p.key}), static RAM{stack}")  # fmt: skip
        for form, s in self.sized.items():
            verdict = "fits" if self.fits(form) else "does not fit"
            mark = " (asked for)" if form == self.form else ""
            out.append(f"  {form:<14} {s.flash:8d} {s.ram:6d}  {verdict}{mark}")
        if self.states:
            each = ", ".join(f"{a} {n} B" for a, n in self.states.items())
            out.append(f"  each axis' state (in the RAM above): {each}")
        out.append(f"  {self.refusal() or f'the {self.form} form fits the {p.key}'}")
        return out


def fit(p: Part, model, form: str, arith: str, files: dict[str, str], prefix: str) -> Fit:
    """Link the part's firmware image with the form asked for (``files``, already emitted) and, fixed
    point, with the other form too. The firmware reads the fixed-point filter of prefix accelnav: for
    another arithmetic or prefix the filter's object alone is sized, and said so."""
    from .generated import generate

    missing = missing_tools(p)
    if missing:
        return Fit(p, form, {}, missing)
    if arith != "fixed" or prefix != "accelnav":
        s = measure(p, files, prefix, form)
        why = f"the firmware links the fixed-point filter of prefix accelnav: {form} filter object alone "
        return Fit(p, form, {}, why + f"{s.flash} B flash, {s.ram} B RAM, not linked: no verdict")
    todo = {form: files}
    for other in FORMS:
        if other != form:
            todo[other] = generate(model, form=other)
    with ThreadPoolExecutor(max_workers=2) as pool:
        states = pool.submit(measure, p, files, prefix, form)
        sized = {s.form: s for s in pool.map(lambda kv: link(p, kv[1], kv[0]), todo.items())}
        return Fit(p, form, sized, None, states.result().states)
