"""The ``--report`` of ``accelnav codegen``: ranges, formats, error bounds, flash and RAM.

Flash and RAM are measured, not estimated: the generated source is compiled
for Cortex-M3 with arm-none-eabi-gcc -O2 and sized with arm-none-eabi-size
(state RAM is the size of the per-axis struct, which the caller allocates).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from accelnav.model.load import Model
from accelnav.native.cbuild import STRICT_WARN

from .bounds import Y_SIGMAS, error_bound_rows, worst_case_bound

ARM_FLAGS = ["-mcpu=cortex-m3", "-mthumb", "-O2", "-ffreestanding", *STRICT_WARN]


def arm_size(files: dict[str, str], prefix: str) -> dict[str, int] | None:
    """text/data/bss of PREFIX.c compiled for Cortex-M3, or None without the toolchain."""
    gcc, size = shutil.which("arm-none-eabi-gcc"), shutil.which("arm-none-eabi-size")
    if not gcc or not size:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        for name, text in files.items():
            Path(tmp, name).write_text(text)
        obj = Path(tmp, f"{prefix}.o")
        subprocess.run([gcc, *ARM_FLAGS, "-c", str(Path(tmp, f"{prefix}.c")), "-o", str(obj)], check=True)
        out = subprocess.run([size, str(obj)], check=True, capture_output=True, text=True).stdout
    text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
    return {"text": text, "data": data, "bss": bss}


def struct_size(header: str, tname: str) -> int:
    """Bytes of a generated struct on the 32-bit target (fields are int32/uint32/int64/float or a
    pointer; 8-byte alignment of int64)."""
    m = re.search(r"typedef struct \{([^{}]*)\} " + re.escape(tname) + ";", header)
    size = 0
    align = 4
    for ctype in re.findall(r"^\s*(?:const )?(?:struct )?(\w+ ?\*?) ?\w+;", m.group(1), re.M):
        w = 8 if ctype.strip() in ("int64_t", "uint64_t", "double") else 4  # a pointer: 4 on the 32-bit targets
        align = max(align, w)
        size = (size + w - 1) // w * w + w
    return (size + align - 1) // align * align


def report(model: Model, *, form: str | None, arith: str, files: dict[str, str], prefix: str) -> str:
    form = form or model.filter.form
    lines = [f"accelnav codegen report: model {model.name} ({model.sha256[:12]}), {arith}, {form} form"]
    lines.append(f"rate {model.rate_hz:g} Hz, declared run {model.ranges.max_run_s:g} s")
    with ThreadPoolExecutor(max_workers=1) as pool:
        # the cross-compile (a second of arm-none-eabi-gcc) runs while the bounds below are computed
        sized = pool.submit(arm_size, files, prefix)
        flash_at = _axes(model, form, arith, files, prefix, lines)
        sz = sized.result()
    if sz:  # each axis' flash line, after its RAM line
        n_ax = len(model.axes)
        flash = (
            f"  flash (Cortex-M3 -O2, all {n_ax} axes): text {sz['text']} B, data {sz['data']} B, "
            f"bss {sz['bss']} B; per axis ~{(sz['text'] + sz['data']) // n_ax} B"
        )
        for at in reversed(flash_at):
            lines.insert(at, flash)
    return "\n".join(lines)


def _axes(model: Model, form: str, arith: str, files: dict[str, str], prefix: str, lines: list[str]) -> list[int]:
    """The report's per-axis blocks, appended to ``lines``; where each axis' flash line goes."""
    from .plan import schedule_for as _schedule_for
    from .ranges import plan_axis

    def bounds(i: int):
        """The axis' plan, schedule, sample rows (1 s, the run's end) and its two bounds there."""
        p = plan_axis(model, i, form)
        sched = _schedule_for(p) if form == "gain_schedule" else None
        at = sorted({min(int(model.rate_hz), p.n_run - 1), p.n_run - 1})
        return p, sched, at, error_bound_rows(p, p.n_run, at, sched), worst_case_bound(p, p.n_run, sched, rows=at)

    done = []
    if arith == "fixed":  # the axes' bounds at once: their recursions run in C, off the interpreter lock
        with ThreadPoolExecutor(max_workers=2) as pool:
            done = list(pool.map(bounds, range(len(model.axes))))
    flash_at = []
    for i, ax in enumerate(model.axes):
        tname = f"{prefix}_{ax.name}_t"
        ram = struct_size(files[f"{prefix}.h"], tname)
        lines.append("")
        lines.append(f"axis {ax.name}: RAM {ram} B (state struct)")
        flash_at.append(len(lines))
        if arith != "fixed":
            continue
        p, sched, at, b, w = done[i]
        lines.append(f"  {'variable':<8} {'range':>12} {'format':>9} {'resolution':>11}  note")
        for v in p.vars.values():
            sat = " (saturates, counted)" if v.saturates else ""
            lines.append(f"  {v.name:<8} {v.bound:12.4g} {v.fmt.name:>9} {v.fmt.lsb:11.3g}  {v.note}{sat}")
        lines.append(f"  {'constant':<8} {'value':>12} {'format':>9}")
        for k, (val, f) in sorted(p.consts.items()):
            lines.append(f"  {k:<8} {val:12.6g} {f.name:>9}")
        if sched is not None:
            lines.append(
                f"  gain schedule: {sched.n_segments} piecewise-linear segments ({(sched.n_segments + 1) * 24} B of "
                "table with its closing row), "
                f"max |K - K64| = " + ", ".join(f"{e:.3g}" for e in sched.max_error) + " [r, v=Ts u, a, eps]"
            )
        names = ("r [m]", "u [m/s]", "a [m/s^2]", "eps [m/s^2]")
        at1 = min(int(model.rate_hz), p.n_run - 1)
        sig = np.array([p.gains.at(k)[1] for k in at])
        at1 = at.index(at1)
        lines.append(
            f"  predicted error bound vs float64 (roundings and gain errors through the closed loop, |y| <= "
            f"{Y_SIGMAS:g} sqrt(S), |a| <= its range; in units of the filter's own sigma in brackets):"
        )
        for j, nm in enumerate(names):
            lines.append(
                f"    {nm:<12} after 1 s {b[at1, j]:.3g} [{b[at1, j] / sig[at1, j]:.2g}]   after "
                f"{model.ranges.max_run_s:g} s {b[-1, j]:.3g} [{b[-1, j] / sig[-1, j]:.2g}]"
            )
        lines.append("  worst case over the declared ranges (every |y| at its bound; rigorous, loose):")
        for j, nm in enumerate(names):
            lines.append(f"    {nm:<12} after 1 s {w[at1, j]:.3g}   after {model.ranges.max_run_s:g} s {w[-1, j]:.3g}")
        lines.append(
            f"  l1 gains of the (a, eps) loop: z->a {p.l1.z_a:.3g}, z->eps {p.l1.z_e:.3g}, "
            f"eps-push->eps {p.l1.e_e:.3g}; skipped-sample gap covered: {p.gap} samples"
        )
    return flash_at
