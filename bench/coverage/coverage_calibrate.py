"""Coverage of ``accelnav calibrate``'s 95 % intervals for still poses in any orientation (3-axis part).

The setting of tests/identify/test_calibrate.py: the default model with a third axis, a 'true' part within 5 mV
(0.13 g) of zero-g and 3 % of sensitivity of it, the tumble_any scenario (random still orientations, 8 s
holds, 3 s turns) converted with the nominal calibration, the gravity-magnitude fit. Prints how many
offset and sensitivity intervals hold the truth, the angle terms' coverage of 0 (the simulated axes are
square), the median |error / se| (0.67 for a standard normal) and the largest errors.
Usage: python bench/run_all.py bench/coverage/coverage_calibrate.py [--seeds 0 200] [--poses 16]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

# tests/support, on the path bench/run_all.py sets
from support.calibrate_cases import any_recording, calibrate_any, nominal, perturbed, truth_offset_scale

from accelnav.identify.calibrate import CalibrationError
from accelnav.model.load import G0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(0, 200), metavar=("FIRST", "END"))
    ap.add_argument("--poses", type=int, default=16)
    args = ap.parse_args()
    nom = nominal(3)
    cov, zs, err_o, err_s, pairs, refused = [], [], [], [], [], []
    t0 = time.perf_counter()
    for seed in range(*args.seeds):
        true = perturbed(nom, np.random.default_rng(300 + seed))
        _, acc = any_recording(nom, true, 200 + seed, args.poses)
        try:
            cal = calibrate_any(nom, acc)
        except CalibrationError as exc:
            refused.append(f"seed {seed}: {exc}")
            continue
        for i, a in enumerate(cal.axes):
            o, s = truth_offset_scale(nom, true, i)
            for lab, est, tr in (("offset", a.offset, o), ("scale", a.scale, s)):
                lo, hi = a.ci95[lab]
                cov.append(lo <= tr <= hi)
                zs.append((est - tr) / a.se[lab])
            err_o.append(abs(a.offset - o) / G0 * 1e3)
            err_s.append(abs(a.scale - s) * 100)
        pairs += [p.ci95[0] <= 0.0 <= p.ci95[1] for p in cal.pairs]
    n = args.seeds[1] - args.seeds[0]
    print(f"{n} seeds, {args.poses} random poses each; refused {len(refused)}; {time.perf_counter() - t0:.0f} s")
    print()
    print("| quantity | value |")
    print("|---|---|")
    print(f"| offsets and sensitivities: truth in the 95 % interval | {sum(cov)}/{len(cov)} |")
    print(f"| angles between axes: 0 in the 95 % interval | {sum(pairs)}/{len(pairs)} |")
    print(f"| median abs(error / se) (0.67 if calibrated) | {np.median(np.abs(zs)):.2f} |")
    print(f"| offset error: median, max | {np.median(err_o):.2g} mg, {max(err_o):.2g} mg |")
    print(f"| sensitivity error: median, max | {np.median(err_s):.2g} %, {max(err_s):.2g} % |")
    for r in refused:
        print(f"  refused: {r}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
