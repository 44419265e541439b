"""Study: the rest detector's shipped defaults on every real recording the suite fetches, against issue 23's targets.

Per recording, ``accelnav smooth`` run as a user would (the CLI, a CSV, a
shipped model at the recording's rate) three ways: ``--zupt auto`` (the
defaults), the reference rests as a mask file, and no ZUPT; the car also with
a GNSS fix every 10 s (the other epochs held out) beside interpolating those
fixes. The data, their references and licences: tests/support/realdata.py (gaitmap's
foot-mounted walk) and tests/support/realdata_more.py (mobgap's lower-back walks,
gtsam's KITTI drive); they are fetched from PyPI by version and sha256 into
ACCELNAV_CACHE_DIR (else ~/.cache/accelnav).

Figures:
* foot walk: mean |stride-length error| over the strides, in cm and in % of
  the mean stride;
* lower-back walks: error of the distance walked between the bout's first
  and last initial contact (motion capture), in m and in %;
* car: along-track rms error at the held-out GNSS epochs with fixes; without
  fixes the rms over the run and the final error in % of the 3.7 km; and how
  long the defaults hold updates while the track says the car moves.

Then the targets table (goal, measured, met). The baselines (reference rests,
no ZUPT, interpolated fixes) come from the same run.
Usage: python bench/run_all.py bench/studies/study_real_rests.py [--verbose-cli]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from pathlib import Path

from support import realdata  # tests/support, on the path bench/run_all.py sets
from support import realdata_more as rm

from accelnav.estimate.zupt import intervals

METHODS = rm.WALK_METHODS
MOVING = 1.0  # m/s: a "rest" held while the GNSS track is faster than this is a false rest


def _quietly(verbose: bool, fn, *args, **kw):
    if verbose:
        return fn(*args, **kw)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return fn(*args, **kw)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--verbose-cli", action="store_true", help="show accelnav smooth's own output")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="study_real_rests_"))
    targets: list[tuple[str, str, str, bool]] = []

    def ratio_row(name: str, auto: float, ref: float, unit: str) -> None:
        targets.append(
            (name, "defaults <= 1.5 x reference rests", f"{auto:.3g} vs {ref:.3g} {unit}", auto <= 1.5 * ref)
        )

    feet = rm.load_or_none("gaitmap foot walk", realdata.load_walk)
    if feet:
        print("\nFoot-mounted walk (gaitmap 2.6.0 example, 204.8 Hz): mean |stride-length error|")
        print(f"{'foot':<8}{'strides':>8}" + "".join(f"{m:>22}" for m in METHODS))
        for foot in feet:
            r = _quietly(args.verbose_cli, rm.study_foot, foot, tmp)
            mean_len = foot.true_length.mean()
            cells = "".join(
                f"{100 * r['error'][m]:>10.1f} cm {100 * r['error'][m] / mean_len:>6.1f} %" for m in METHODS
            )
            print(f"{foot.name:<8}{len(foot.true_length):>8}{cells}")
            auto, ref = r["error"]["defaults"], r["error"]["reference rests"]
            ratio_row(f"foot {foot.name}", 100 * auto, 100 * ref, "cm")
            pct = 100 * auto / mean_len
            targets.append((f"foot {foot.name}", "defaults <= 3 % of distance", f"{pct:.1f} %", pct <= 3.0))

    walks = rm.load_or_none("mobgap lower-back walks", rm.load_lowback_walks)
    if walks:
        print("\nLower-back walks (mobgap 1.2.0 example, 100 Hz): distance between first and last contact")
        print(f"{'walk':<15}{'true [m]':>9}" + "".join(f"{m:>22}" for m in METHODS) + f"{'rests found / true [s]':>26}")
        for w in walks:
            r = _quietly(args.verbose_cli, rm.study_walk, w, tmp)
            e = r["error"]
            cells = "".join(f"{e[m]:>+10.2f} m {100 * e[m] / w.length:>+7.1f} %" for m in METHODS)
            found = f"{r['rest'].sum() / rm.WALK_RATE:.2f} / {w.rest.sum() / rm.WALK_RATE:.2f}"
            print(f"{w.name:<15}{w.length:>9.2f}{cells}{found:>26}")
            auto, ref = abs(e["defaults"]), abs(e["reference rests"])
            ratio_row(f"walk {w.name}", auto, ref, "m")
            pct = 100 * auto / w.length
            targets.append((f"walk {w.name}", "defaults <= 3 % of distance", f"{pct:.1f} %", pct <= 3.0))

    drive = rm.load_or_none("KITTI drive", rm.load_drive)
    if drive:
        r = _quietly(args.verbose_cli, rm.study_drive, drive, tmp)
        total = drive.distance[-1]
        print(f"\nCar (KITTI via gtsam 4.3.0, 100 Hz, {drive.t[-1]:.0f} s, {total:.0f} m): along-track distance")
        print(f"{'method':<20}{'fix every 10 s: rms':>20}{'no fixes: rms':>16}{'final':>12}{'final/dist':>12}")
        for m in METHODS:
            rms, final = r["free"][m]
            print(f"{m:<20}{r['fixed'][m]:>18.2f} m{rms:>14.0f} m{final:>10.0f} m{100 * final / total:>10.1f} %")
        print(f"{'interpolated fixes':<20}{r['fixed']['interpolated fixes']:>18.2f} m")
        auto = r["rests"]["defaults"]
        false = [(a, b) for a, b in intervals(auto) if drive.speed[a:b].max() > MOVING]
        held = sum(b - a for a, b in false) / rm.DRIVE_RATE
        top = max((drive.speed[a:b].max() for a, b in false), default=0.0)
        print(
            f"defaults: {len(intervals(auto))} rests held ({auto.sum() / rm.DRIVE_RATE:.1f} s), {len(false)} of them"
            f" ({held:.1f} s) while the car moves at more than {MOVING} m/s (up to {top:.1f} m/s);"
            f" reference: {len(intervals(drive.rest))} stop, {drive.rest.sum() / rm.DRIVE_RATE:.1f} s"
        )
        ratio_row("car, fixes 10 s", r["fixed"]["defaults"], r["fixed"]["reference rests"], "m rms")
        ratio_row("car, no fixes", r["free"]["defaults"][0], r["free"]["reference rests"][0], "m rms")
        targets.append(("car", f"no rest while moving > {MOVING} m/s", f"{len(false)} rests, {held:.1f} s", not false))
        targets.append(
            (
                "car, fixes 10 s",
                "defaults <= interpolating the fixes",
                f"{r['fixed']['defaults']:.2f} vs {r['fixed']['interpolated fixes']:.2f} m",
                r["fixed"]["defaults"] <= r["fixed"]["interpolated fixes"],
            )
        )

    print("\nIssue 23 targets, shipped defaults:")
    print()
    print("| recording | goal | measured | met |")
    print("|---|---|---|---|")
    for name, goal, measured, met in targets:
        print(f"| {name} | {goal} | {measured} | {'yes' if met else 'NO'} |")
    print()
    print(f"met {sum(t[3] for t in targets)} of {len(targets)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
