"""Benchmark: the rest decision (issue 31) on every simulated case and real recording, as a user runs accelnav.

Every case goes through the commands with shipped defaults: ``accelnav sim --scenario X --out run.npz
[--fixes-out fixes.csv]`` for the simulated ones (issue 31's cases and the plain walk), a CSV and a shipped
model for the real recordings (tests/support/realdata.py, realdata_more.py: gaitmap's foot walk, mobgap's
lower-back walks (in the level frame made from their reference standings, in accelnav.level's from the
recording alone and in accelnav.level's told those standings), the KITTI drive and the two HGuide n380 drives
with stops), then ``accelnav smooth`` three ways from the same run: ``--zupt auto`` (the defaults), the true
rests as a mask (``--zupt run.npz``, its ``rest``; the reference rests for a real recording) and no ZUPT;
where the case has fixes, each of the three again with ``--fixes`` ("fixes alone" is fixes without ZUPT), and
for the 1 Hz GNSS case fix-to-fix double integration (accelnav.estimate.pipeline.fix_baselines). highway_gnss
runs on the default model with a 20 m/s prior on the start speed (it starts on the road; the shipped prior
asserts u = 0 at sample 0, which alone costs 12 m rms). Figures: position error against the truth, rms over
the run of the distance over all axes (walks: mean |stride-length error| between stance midpoints), mean over
the seeds; rests the defaults accepted while the body moved faster than 0.5 m/s; the cost of the decision per
sample against the plain smoother. Then the targets table (goal | measured | met) that bench/run_all.py
gathers; the baselines (true rests, no ZUPT, fixes alone, fix-to-fix) come from the same run.

Usage: python bench/run_all.py bench/speed/bench_rest_hypotheses.py [--seeds 2] [--no-real]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
import time
from pathlib import Path

import numpy as np
from support import realdata  # tests/support, on the path bench/run_all.py sets
from support import realdata_more as rm
from support.cart_model import adxl335_model

from accelnav.data.runfile import load_run
from accelnav.estimate.pipeline import fix_baselines, stride_errors
from accelnav.estimate.zupt import intervals
from accelnav.hil_sim.sim.trajectories import town_drive_end
from accelnav.model.load import DEFAULT_MODEL
from accelnav.resources import models_dir

MOVING = 0.5  # m/s: a rest accepted while the body moves faster than this is a false rest
PARKED_S = 20.0  # town_drive: simulated this long past the end of the drive
CASES = [  # (scenario, model, seconds (None: town_drive's whole drive), kind)
    ("highway_gnss", "moving start", 300.0, "vehicle"),
    ("town_drive", "default", None, "vehicle"),
    ("tilting_mount", "default", 300.0, "tilt"),
    ("hand_box", "adxl335", 120.0, "box"),
    ("walking", "foot", 60.0, "walk"),
    ("walking_still_start", "foot", 60.0, "still start"),
    ("jogging", "foot", 60.0, "jog"),
]
METHODS = ("defaults", "true rests", "no ZUPT")


def cli(argv: list[str]) -> str:
    """Run one accelnav command in-process; its printed output. A refusal fails loudly."""
    from accelnav.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    if code != 0:
        raise RuntimeError(f"accelnav {' '.join(argv)}: exit status {code}: {err.getvalue().strip()}")
    return out.getvalue()


def model_files(tmp: Path) -> dict[str, Path | None]:
    box = tmp / "adxl335_cart.toml"
    box.write_text(adxl335_model().text)
    # highway_gnss starts on the road: the shipped prior (u = 0 exactly at sample 0) would cost the smoother
    # 12 m rms over its first 30 s whatever the rests; a user who knows that widens the speed's prior
    text = DEFAULT_MODEL.read_text()
    prior = "initial_sigma = [0.0, 0.0, 0.05, 0.05]"
    assert text.count(prior) == 1, "the default model's prior line moved"
    moving = tmp / "adxl250_moving_start.toml"
    moving.write_text(text.replace(prior, "initial_sigma = [0.0, 20.0, 0.05, 0.05]"))
    return {"default": None, "foot": models_dir() / "foot_imu.toml", "adxl335": box, "moving start": moving}


def false_rests(applied: np.ndarray, speed: np.ndarray) -> tuple[int, float]:
    """(count, top speed) of the applied rests during which the true speed exceeded MOVING."""
    bad = [float(speed[a:b].max()) for a, b in intervals(applied) if speed[a:b].max() > MOVING]
    return len(bad), max(bad, default=0.0)


def false_cell(counts: list[int], top: float) -> str:
    """The false rests of the defaults without fixes [and with], and the top speed among them."""
    where = " / ".join(map(str, counts)) + (" (no fixes / fixes)" if len(counts) > 1 else "")
    return f"{where}, up to {top:.1f} m/s"


def simulated(scenario: str, model: Path | None, seconds: float | None, seed: int, tmp: Path) -> dict:
    """One seed of one case: the figures of each way of running smooth."""
    if seconds is None:
        seconds = town_drive_end(np.random.SeedSequence(seed).spawn(1)[0]) + PARKED_S
    run = tmp / f"{scenario}_{seed}.npz"
    fixes = tmp / f"{scenario}_{seed}_fixes.csv"
    argv = ["sim", "--scenario", scenario, "--duration", f"{seconds:.2f}", "--seed", str(seed), "--out", str(run)]
    argv += [] if model is None else ["--model", str(model)]
    has_fixes = scenario in ("highway_gnss", "town_drive", "hand_box")
    cli(argv + (["--fixes-out", str(fixes)] if has_fixes else []))
    truth, smodel = load_run(run)
    truth["rest"] = truth["rest"] if "rest" in truth else truth["stance"]  # the plain walk has its stances
    speed = np.linalg.norm(truth["u"], axis=1)
    mask = tmp / f"{scenario}_{seed}_rests.csv"
    np.savetxt(mask, truth["rest"].astype(int), header="rest", comments="", fmt="%d")
    zupt = {"defaults": "auto", "true rests": mask if truth["rest"].any() else None, "no ZUPT": None}
    res = {"rms": {}, "stride": {}, "false": {}, "first stand": None, "samples": len(truth["t"])}
    for given in (None, fixes) if has_fixes else (None,):
        tag = "" if given is None else " + fixes"
        for method, rest in zupt.items():
            out = rm.smooth_command(run, [], rest=rest, fixes=given)
            r = out["smooth_x"][:, :, 0]  # (axes, N)
            res["rms"][method + tag] = float(np.sqrt(np.mean(np.sum((r.T - truth["r"]) ** 2, axis=1))))
            if "stance" in truth:
                res["stride"][method + tag] = stride_errors(truth, {method: r})[0].mean_abs
            if method == "defaults":
                applied = out["zupt"].any(axis=1)
                res["false"][tag or " alone"] = false_rests(applied, speed)
                a, b = intervals(truth["rest"])[0] if truth["rest"].any() else (0, 0)
                res["first stand"] = (int(applied[a:b].sum()), b - a, a / float(smodel.rate_hz))
            if method == "no ZUPT" and given is not None:
                # the run file holds the outputs, not the input (the compact default): the input's from the sim
                base = fix_baselines({**out, "accel": truth["accel"], "clipped": truth["clipped"]}, smodel)
                for name, est in base.items():
                    res["rms"][name] = float(np.sqrt(np.mean(np.sum((est.T - truth["r"]) ** 2, axis=1))))
    return res


def cost_per_sample(run: Path, repeat: int = 5) -> dict[str, float]:
    """Wall time per sample of smooth plain, with the true rests and with --zupt auto, µs (best of ``repeat``)."""
    from baselines import best_of  # bench/common, on the path bench/run_all.py sets

    n = len(np.load(run)["t"])
    ways = {"plain": None, "true rests": run, "defaults": "auto"}
    return {k: 1e6 * best_of(lambda z=z: rm.smooth_command(run, [], rest=z), repeat) / n for k, z in ways.items()}


def mean_of(rows: list[dict], key: str, method: str) -> float:
    return float(np.mean([r[key][method] for r in rows]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--no-real", action="store_true", help="only the simulated cases")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_rest_hypotheses_"))
    models = model_files(tmp)
    targets: list[tuple[str, str, str, bool]] = []
    t0 = time.perf_counter()

    print(
        f"Simulated cases, {args.seeds} seeds each; position error rms over the run, m (walks: mean |stride "
        "error|, cm); defaults' false rests: accepted while the truth moves > 0.5 m/s"
    )
    print()
    print(
        "| case | model | s | defaults | true rests | no ZUPT | + fixes: defaults | true rests | fixes alone "
        "| fix-to-fix | false rests (no fixes / fixes) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    results = {}
    for scenario, mname, seconds, kind in CASES:
        rows = [simulated(scenario, models[mname], seconds, s, tmp) for s in range(1, args.seeds + 1)]
        results[scenario] = rows
        walk = kind in ("walk", "still start", "jog")
        key, scale = ("stride", 100.0) if walk else ("rms", 1.0)

        def cell(method: str, rows=rows, key=key, scale=scale) -> str:
            return f"{scale * mean_of(rows, key, method):.3g}" if method in rows[0][key] else "-"

        fr = [sum(r["false"][t][0] for r in rows) for t in rows[0]["false"]]
        dur = np.mean([r["samples"] for r in rows]) / (200.0 if mname == "foot" else 100.0)
        cells = [cell(m) for m in METHODS] + [cell(m + " + fixes") for m in METHODS]
        cells += [
            f"{mean_of(rows, 'rms', 'fix-to-fix integration'):.3g}"
            if "fix-to-fix integration" in rows[0]["rms"]
            else "-",
            " / ".join(map(str, fr)),
        ]
        print(f"| {scenario} | {mname} | {dur:.0f} | " + " | ".join(cells) + " |", flush=True)

        if kind in ("vehicle", "tilt"):
            top = max(r["false"][t][1] for r in rows for t in r["false"])
            targets.append((scenario, "rests accepted at speed > 0.5 m/s = 0", false_cell(fr, top), sum(fr) == 0))
        if "defaults + fixes" in rows[0]["rms"]:
            auto, alone = mean_of(rows, "rms", "defaults + fixes"), mean_of(rows, "rms", "no ZUPT + fixes")
            if kind == "vehicle":
                targets.append(
                    (
                        scenario,
                        "with fixes: defaults <= 1.05 x no ZUPT",
                        f"{auto:.3g} vs {alone:.3g} m",
                        auto <= 1.05 * alone,
                    )
                )
            targets.append(
                (
                    scenario,
                    "with fixes: defaults <= 1.1 x fixes alone",
                    f"{auto:.3g} vs {alone:.3g} m",
                    auto <= 1.1 * alone,
                )
            )
        if scenario == "highway_gnss":
            auto, f2f = mean_of(rows, "rms", "defaults + fixes"), mean_of(rows, "rms", "fix-to-fix integration")
            targets.append(
                (
                    scenario,
                    "1 Hz GNSS: defaults <= fix-to-fix double integration",
                    f"{auto:.3g} vs {f2f:.3g} m",
                    auto <= f2f,
                )
            )
        auto, ref = mean_of(rows, key, "defaults"), mean_of(rows, key, "true rests")
        unit = "cm/stride" if walk else "m"
        if kind in ("walk", "still start"):
            targets.append(
                (
                    scenario,
                    "defaults <= 1.2 x true rests",
                    f"{scale * auto:.3g} vs {scale * ref:.3g} {unit}",
                    auto <= 1.2 * ref,
                )
            )
        if kind == "still start":
            used = [r["first stand"] for r in rows]
            ok = all(u > 0 for u, _, _ in used)
            what = ", ".join(f"{u}/{n} samples" for u, n, _ in used)
            targets.append((scenario, f"still start {used[0][2]:.1f} s in anchors", f"first stand: {what} used", ok))
        if kind in ("tilt", "jog"):
            targets.append(
                (
                    scenario,
                    "defaults <= 3 x true rests",
                    f"{scale * auto:.3g} vs {scale * ref:.3g} {unit}",
                    auto <= 3 * ref,
                )
            )

    if not args.no_real:
        real(tmp, targets)

    run = tmp / "town_drive_1.npz"
    cost = cost_per_sample(run)
    ratio = cost["defaults"] / cost["plain"]
    print(
        f"\nCost per sample, smooth of town_drive seed 1 ({len(np.load(run)['t'])} samples x 2 axes, the command "
        f"with its file output): plain {cost['plain']:.2f} µs, true rests {cost['true rests']:.2f} µs, "
        f"--zupt auto {cost['defaults']:.2f} µs"
    )
    targets.append(
        (
            "decision cost",
            "--zupt auto <= 3 x plain smoother per sample",
            f"{ratio:.2f} x ({cost['defaults']:.2f} vs {cost['plain']:.2f} µs)",
            ratio <= 3.0,
        )
    )

    print("\nIssue 31 targets, shipped defaults:\n")
    print("| case | goal | measured | met |")
    print("|---|---|---|---|")
    for name, goal, measured, met in targets:
        print(f"| {name} | {goal} | {measured} | {'yes' if met else 'NO'} |")
    print(f"\nmet {sum(t[3] for t in targets)} of {len(targets)}; {time.perf_counter() - t0:.0f} s")
    return 0


def real(tmp: Path, targets: list) -> None:
    """The real recordings of the tests, through the command (rm.smooth_cli)."""
    feet = rm.load_or_none("gaitmap foot walk", realdata.load_walk)
    print("\nReal recordings (tests/support): defaults | reference rests | no ZUPT")
    for foot in feet or ():
        e = rm.study_foot(foot, tmp, smooth=rm.smooth_cli)["error"]
        auto, ref, none = (100 * e[m] for m in rm.WALK_METHODS)
        print(f"gaitmap foot walk, {foot.name}: mean |stride error| {auto:.2f} | {ref:.2f} | {none:.1f} cm")
        targets.append(
            (
                f"foot walk {foot.name}",
                "defaults <= 1.2 x reference rests",
                f"{auto:.2f} vs {ref:.2f} cm/stride",
                auto <= 1.2 * ref,
            )
        )
    frames = (
        ("hand", ""),
        ("library", ", accelnav.level frame"),
        ("library at standings", ", accelnav.level at standings"),
    )
    for frame, tag in frames:
        # the frame made here from the reference standings, accelnav.level's from the recording alone (a user's),
        # and accelnav.level's told the reference standings
        for w in rm.load_or_none("mobgap lower-back walks", lambda f=frame: rm.load_lowback_walks(frame=f)) or ():
            e = rm.study_walk(w, tmp, smooth=rm.smooth_cli)["error"]
            auto, ref, none = (abs(e[m]) for m in rm.WALK_METHODS)
            print(
                f"mobgap lower-back walk {w.name}{tag} ({w.length:.2f} m): |distance error| {auto:.2f} | {ref:.2f} | "
                f"{none:.2f} m"
            )
            targets.append(
                (
                    f"lower-back walk {w.name}{tag}",
                    "defaults <= 1.2 x reference rests",
                    f"{auto:.2f} vs {ref:.2f} m",
                    auto <= 1.2 * ref,
                )
            )
    drive = rm.load_or_none("KITTI drive", rm.load_drive)
    if drive is not None:
        vehicle("KITTI drive", drive, tmp, targets)
    for key, drive in (rm.load_or_none("HGuide n380 drives", rm.load_n380_drives) or {}).items():
        vehicle(f"n380 {key} drive", drive, tmp, targets)


def vehicle(name: str, drive, tmp: Path, targets: list) -> None:
    r = rm.study_drive(drive, tmp, smooth=rm.smooth_cli)
    fr = [false_rests(r[k]["defaults"], drive.speed) for k in ("free_rests", "rests")]
    f = r["fixed"]
    print(
        f"{name} ({drive.t[-1]:.0f} s, {drive.distance[-1]:.0f} m): no fixes rms {r['free']['defaults'][0]:.1f} | "
        f"{r['free']['reference rests'][0]:.1f} | {r['free']['no ZUPT'][0]:.1f} m; fix every {rm.FIX_EVERY_S} s, "
        f"held-out rms {f['defaults']:.2f} | {f['reference rests']:.2f} | {f['no ZUPT']:.2f} m (interpolated fixes "
        f"{f['interpolated fixes']:.2f} m); defaults' false rests {fr[0][0]} / {fr[1][0]} (no fixes / fixes)"
    )
    counts, top = [n for n, _ in fr], max(fr[0][1], fr[1][1])
    targets.append((name, "rests accepted at speed > 0.5 m/s = 0", false_cell(counts, top), sum(counts) == 0))
    auto, alone = f["defaults"], f["no ZUPT"]
    targets.append(
        (name, "with fixes: defaults <= 1.05 x no ZUPT", f"{auto:.3g} vs {alone:.3g} m", auto <= 1.05 * alone)
    )
    targets.append(
        (name, "with fixes: defaults <= 1.1 x fixes alone", f"{auto:.3g} vs {alone:.3g} m", auto <= 1.1 * alone)
    )


if __name__ == "__main__":
    raise SystemExit(main())
