"""Build and run the libFuzzer harness of the firmware's receive path (fuzz_rx.c).

    python firmware/fuzz/fuzz.py corpus             # rewrite the seed corpus from the frame layout
    python firmware/fuzz/fuzz.py run --seconds 600  # build, then fuzz (make fuzz)
    python firmware/fuzz/fuzz.py merge              # minimise build/fuzz/corpus into grown/ (make fuzz-merge)

The harness is compiled with clang (-fsanitize=fuzzer,address,undefined) against the firmware's
sources and the generated frame code and filter of a model, written by the project's generator
into the output folder (never into the source tree). A developer tool beside the harness, not
package data: it reads its own folder for fuzz_rx.c and the seeds.

The seed corpus (corpus/) holds one small input per frame kind and a few sessions, in both of the
harness's modes (see fuzz_rx.c): raw inputs are the wire bytes of valid frames, structured ones the
harness's operation lists. It is generated from the manifest, so a layout change is one
`corpus` run away.

What fuzzing found carries from one run to the next through two more folders in the repository:

* grown/: the inputs that reach coverage the seeds do not, from long runs (`make fuzz`, whose corpus
  stays in build/fuzz/corpus), minimised by libFuzzer's ``-merge=1`` (`make fuzz-merge`): the seeds
  come first, so only inputs adding features to them and to each other are kept. Kept under
  GROWN_MAX_BYTES: a merge that would pass it is refused (fuzz with a smaller ``-max_len``).
* regressions/: every failing input a run found (copied there by `run`); once the bug is fixed
  it stays, and tests/firmware/test_fuzz_rx.py replays it with the seeds and grown/ every run.

CI's bounded run starts from seeds + grown/, so each long run's coverage is where the next starts.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
HARNESS = HERE / "fuzz_rx.c"
SEEDS = HERE / "corpus"
GROWN = HERE / "grown"
REGRESSIONS = HERE / "regressions"
GROWN_MAX_BYTES = 64 * 1024  # the repository's corpus stays small enough to review and to load in a second
FW_SRC = ("app.c", "link.c", "cobs.c", "crc32.c", "filter_adapter.c")
SANITIZE = ["-fsanitize=fuzzer,address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]


class FuzzError(RuntimeError):
    """The harness could not be built (no clang, no fuzzer runtime, a compile error)."""


def clang() -> str | None:
    return shutil.which("clang")


def runtime_missing(out: Path) -> str | None:
    """Why clang cannot link a libFuzzer target here (no clang, no fuzzer runtime), or None if it can."""
    cc = clang()
    if cc is None:
        return "clang not found (Debian: clang libclang-rt-14-dev)"
    out.mkdir(parents=True, exist_ok=True)
    probe = out / "probe.c"
    probe.write_text(
        "#include <stddef.h>\nint LLVMFuzzerTestOneInput(const unsigned char *d, size_t n)\n"
        "{\n    (void)d;\n    (void)n;\n    return 0;\n}\n"
    )
    done = subprocess.run([cc, *SANITIZE, str(probe), "-o", str(out / "probe")], capture_output=True, text=True)
    if done.returncode != 0:
        return f"clang cannot link -fsanitize=fuzzer (Debian: libclang-rt-14-dev): {done.stderr.strip()[-200:]}"
    return None


def build(out: Path, model: str | None = None) -> Path:
    """Generate the model's C into out/gen and link the harness to out/fuzz_rx; returns its path."""
    from accelnav.hil_sim.targets.firmware import STRICT, generated
    from accelnav.resources import firmware_dir

    cc = clang()
    if cc is None:
        raise FuzzError("clang not found (Debian: clang libclang-rt-14-dev)")
    fw = firmware_dir()
    gen = out / "gen"
    gen.mkdir(parents=True, exist_ok=True)
    for name, text in generated(model).items():
        path = gen / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
    inc = [f"-I{fw / 'src'}", f"-I{fw / 'boards'}", f"-I{gen}"]
    objs = []
    # the generated filter keeps helpers only some models call: clang (unlike gcc) warns on unused
    # static inline functions, so that one warning is off for the generated files alone
    for src in ("accelnav.c", "acnframe.c"):
        obj = out / (src[:-2] + ".o")
        _cc([cc, *STRICT, *SANITIZE, "-Wno-unused-function", *inc, "-c", str(gen / src), "-o", str(obj)])
        objs.append(str(obj))
    exe = out / "fuzz_rx"
    srcs = [str(HARNESS)] + [str(fw / "src" / s) for s in FW_SRC]
    _cc([cc, *STRICT, *SANITIZE, *inc, *srcs, *objs, "-o", str(exe)])
    return exe


RSS_MB = 1024  # the memory a harness may use of its own


def rss_limit() -> str:
    """libFuzzer's ``-rss_limit_mb`` for a harness started from this process: RSS_MB above this process's peak.
    Linux carries a parent's peak RSS into its child's ``ru_maxrss`` across fork and exec, which libFuzzer reads
    as its own: started from a test run holding 1.4 GB, a harness was "out of memory" before its first input."""
    import resource

    return f"-rss_limit_mb={RSS_MB + resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024}"


def _cc(cmd: list[str]) -> None:
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        raise FuzzError(f"{' '.join(cmd)} failed:\n{done.stderr[-4000:]}")


def run(exe: Path, seconds: int, out: Path, seeds: Path = SEEDS, fresh: bool = False) -> dict:
    """Fuzz for ``seconds`` from the seeds and the grown corpus; returns libFuzzer's figures and any inputs
    that failed.

    New inputs go to out/corpus (kept between runs unless ``fresh``), failing ones to out/crashes/; the
    repository's folders are only read.
    """
    work, crashes = out / "corpus", out / "crashes"
    if fresh and work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    crashes.mkdir(parents=True, exist_ok=True)
    before = set(crashes.iterdir())
    cmd = [
        str(exe),
        f"-max_total_time={seconds}",
        "-print_final_stats=1",
        "-timeout=10",
        rss_limit(),
        f"-artifact_prefix={crashes}/",
        str(work),
        str(seeds),
        *([str(GROWN)] if GROWN.is_dir() else []),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=seconds + 300)
    figures = parse(done.stderr)
    figures["returncode"] = done.returncode
    figures["artifacts"] = sorted(str(p) for p in set(crashes.iterdir()) - before)
    figures["log_tail"] = done.stderr[-6000:]
    figures["command"] = " ".join(cmd)
    return figures


def replay(exe: Path, inputs: list[Path], timeout_s: int = 300) -> subprocess.CompletedProcess:
    """Run the harness once on each of ``inputs`` (libFuzzer runs files given by name and exits): a failing
    one aborts with a non-zero status and its name in the log."""
    cmd = [str(exe), "-timeout=10", rss_limit(), *map(str, inputs)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)


def committed_inputs() -> list[Path]:
    """Every input the repository keeps: the seeds, grown/ and regressions/."""
    return sorted(p for d in (SEEDS, GROWN, REGRESSIONS) if d.is_dir() for p in d.iterdir() if p.is_file())


def keep_findings(artifacts: list[str], folder: Path = REGRESSIONS) -> list[Path]:
    """Copy the failing inputs a run found into ``folder`` (named by content: the same input once)."""
    import hashlib

    folder.mkdir(parents=True, exist_ok=True)
    kept = []
    for a in artifacts:
        data = Path(a).read_bytes()
        kind = Path(a).name.split("-", 1)[0]  # crash, leak, timeout, oom
        path = folder / f"{kind}-{hashlib.sha1(data).hexdigest()[:16]}"
        if not path.exists():
            path.write_bytes(data)
        kept.append(path)
    return kept


def merge(exe: Path, runs: list[Path], work: Path) -> dict:
    """Minimise grown/ plus the corpora of ``runs`` into grown/ with ``-merge=1`` over the seeds: (figures)."""
    stage = work / "merge"
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    seed_names = set()
    for p in SEEDS.iterdir():  # the seeds first: their features count as had, so no input repeats them
        shutil.copyfile(p, stage / p.name)
        seed_names.add(p.name)
    sources = [d for d in (GROWN, *runs) if d.is_dir()]
    cmd = [str(exe), "-merge=1", "-timeout=10", rss_limit(), str(stage), *map(str, sources)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    if done.returncode != 0:
        raise FuzzError(f"{' '.join(cmd)} failed:\n{done.stderr[-4000:]}")
    keep = {p.name: p.read_bytes() for p in stage.iterdir() if p.name not in seed_names}
    size = sum(map(len, keep.values()))
    if size > GROWN_MAX_BYTES:
        raise FuzzError(
            f"the merged corpus holds {size} bytes in {len(keep)} inputs, over {GROWN_MAX_BYTES}: grown/ left "
            "as it was; fuzz with a smaller -max_len or merge fewer runs"
        )
    before = {p.name for p in GROWN.iterdir()} if GROWN.is_dir() else set()
    GROWN.mkdir(exist_ok=True)
    for name in before - set(keep):
        (GROWN / name).unlink()
    for name, data in keep.items():
        (GROWN / name).write_bytes(data)
    return {"inputs": len(keep), "bytes": size, "added": len(set(keep) - before), "dropped": len(before - set(keep))}


def parse(log: str) -> dict:
    """cov/ft after loading the seeds (INITED) and at the end (DONE), and the final stats."""
    out: dict = {}
    for tag in ("INITED", "DONE"):
        m = re.findall(rf"#(\d+)\s+{tag}\s+cov: (\d+) ft: (\d+)", log)
        if m:
            out[f"{tag.lower()}_cov"], out[f"{tag.lower()}_ft"] = int(m[-1][1]), int(m[-1][2])
    for key in ("number_of_executed_units", "average_exec_per_sec", "new_units_added", "peak_rss_mb"):
        m = re.search(rf"stat::{key}:\s+(\d+)", log)
        if m:
            out[key] = int(m.group(1))
    return out


# ---- the seed corpus ---------------------------------------------------------------------------


def seeds(model: str | None = None) -> dict[str, bytes]:
    """Named seed inputs built from the model's frame layout (see fuzz_rx.c for the two modes)."""
    import numpy as np

    from accelnav.hil_sim.targets.firmware import manifest
    from accelnav.link.codec import encode_command, encode_stimulus, pack_payload

    man = manifest(model)
    n_axes = len(man.axes)
    raw_key = man.raw_fields()
    mid = {k: np.full((1, n_axes), 2048 if k == "code" else 1000) for k in raw_key}
    commands = [k[4:] for k in man.frames if k.startswith("cmd_")]
    stim_payload = pack_payload(man, "stimulus", {f"{ax}.{k}": 2048 for ax in man.axes for k in raw_key})

    def cmd(name: str, **kw) -> bytes:
        return encode_command(man, name, **kw)

    def op_frame(payload: bytes, ch: int = 0) -> bytes:
        return bytes([0 | ch << 2, len(payload)]) + payload

    def op_burst(k: int) -> bytes:  # k + 1 stimulus frames of the mid-scale input
        return bytes([3, k]) + stim_payload[1:]

    out: dict[str, bytes] = {}
    for name in commands:  # raw: each command alone, on the host channel
        kw = {"factor": 4} if name == "decimate" else {}
        out[f"raw-{name}"] = b"\x00" + cmd(name, **kw)
    out["raw-stimulus"] = b"\x02" + encode_stimulus(man, **mid)  # on the stimulus channel
    out["raw-session"] = (
        b"\x00" + cmd("info") + encode_stimulus(man, **mid) + cmd("decimate", factor=2) + cmd("stop") + cmd("start")
    )
    # structured: sessions that reach blocks, checkpoints, modes and missed samples in a few bytes
    p = {n: pack_payload(man, f"cmd_{n}", {"factor": 3} if n == "decimate" else {}) for n in commands}
    out["ops-compact"] = b"\x01" + op_burst(40) + op_frame(p["zupt_begin"]) + op_burst(255) + op_frame(p["flush"])
    out["ops-states"] = (
        b"\x01" + op_frame(p["mode_states"]) + op_burst(5) + op_frame(p["decimate"]) + op_burst(9) + op_frame(p["info"])
    )
    out["ops-pause"] = (
        b"\x01" + op_burst(20) + op_frame(p["stop"]) + op_burst(3) + op_frame(p["start"]) + bytes([2, 50]) + op_burst(7)
    )
    out["ops-reset"] = b"\x01" + op_burst(30) + op_frame(p["reset"]) + op_burst(30) + op_frame(p["mode_compact"])
    return out


def write_corpus(folder: Path = SEEDS, model: str | None = None) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.iterdir():
        old.unlink()
    paths = []
    for name, data in seeds(model).items():
        path = folder / name
        path.write_bytes(data)
        paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="firmware/fuzz/fuzz.py", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("corpus", help="rewrite the seed corpus from the frame layout")
    c.add_argument("--model")
    r = sub.add_parser("run", help="build the harness and fuzz")
    r.add_argument("--seconds", type=int, default=600)
    r.add_argument("--out", type=Path, default=Path("build/fuzz"))
    r.add_argument("--model")
    m = sub.add_parser("merge", help="minimise the runs' corpora and grown/ into grown/ (libFuzzer -merge=1)")
    m.add_argument("runs", type=Path, nargs="*", default=[Path("build/fuzz/corpus")])
    m.add_argument("--out", type=Path, default=Path("build/fuzz"))
    m.add_argument("--model")
    args = ap.parse_args(argv)
    if args.what == "corpus":
        paths = write_corpus(model=args.model)
        print(f"{len(paths)} seeds, {sum(p.stat().st_size for p in paths)} bytes in {SEEDS}")
        return 0
    try:
        exe = build(args.out, args.model)
    except FuzzError as e:
        print(f"fuzz: {e}", file=sys.stderr)
        return 2
    if args.what == "merge":
        try:
            fig = merge(exe, args.runs, args.out)
        except FuzzError as e:
            print(f"fuzz: {e}", file=sys.stderr)
            return 2
        print(" ".join(f"{k}={v}" for k, v in fig.items()) + f" in {GROWN} (commit it)")
        return 0
    fig = run(exe, args.seconds, args.out)
    tail = fig.pop("log_tail")
    if fig["returncode"]:
        print(tail, end="")
    print(" ".join(f"{k}={v}" for k, v in fig.items()))
    if fig["returncode"] != 0 or fig["artifacts"]:
        kept = keep_findings(fig["artifacts"])
        print(f"fuzz: failed; reproduce with {exe} {' '.join(map(str, kept))}", file=sys.stderr)
        print(f"fuzz: {len(kept)} input(s) kept in {REGRESSIONS}: commit them with the fix", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
