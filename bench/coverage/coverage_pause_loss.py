"""Loss counts around pauses and mode changes: the corruptor with pauses, 300 trials (issue 30).

Each trial damages the firmware's telemetry of a session that stops, starts and changes between the
compact and the state mode (tests/support/compact_corruptor.py) with one fault, decodes it in pieces
of random size and compares ``lost`` with the samples the firmware sent in the span the damaged stream
covers. Exact: delivered + lost == sent; under / over: by how much. The rows' content and order are
checked too (the test's properties). Baseline: main before this change, as the issue measured it: 27 of
270 trials wrong (14 under by 1-6, 13 over by 205-400).

    python bench/run_all.py bench/coverage/coverage_pause_loss.py [--trials 300]
"""

from __future__ import annotations

import argparse
import time

from support.compact_corruptor import PAUSE_FAULTS, pause_session, pause_trial


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=300)
    args = ap.parse_args()
    from accelnav.link.decoder import replay_for
    from accelnav.model.load import load_model

    man, _, frames, truth = pause_session()
    session = (man, replay_for(man, load_model()), frames, truth)
    per = {k: [0, 0, 0, 0, [], 0] for k in PAUSE_FAULTS}  # trials, exact, under, over, misses, other broken
    t0 = time.perf_counter()
    for t in range(args.trials):
        kind, broken, diff = pause_trial(t, session)
        p = per[kind]
        p[0] += 1
        p[1 if diff == 0 else 2 if diff < 0 else 3] += 1
        if diff:
            p[4].append(diff)
        p[5] += any("delivered" not in b for b in broken)
    took = time.perf_counter() - t0
    print(f"{args.trials} trials, {len(frames)} frames and {len(truth)} samples per session ({took:.0f} s)\n")
    print("| fault | trials | exact | under | over | misses | rows wrong or out of order |")
    print("|---|---|---|---|---|---|---|")
    tot = [0, 0, 0, 0, 0]
    for k, (n, ex, un, ov, miss, other) in per.items():
        print(f"| {k} | {n} | {ex} | {un} | {ov} | {', '.join(map(str, sorted(set(miss)))) or '-'} | {other} |")
        tot = [a + b for a, b in zip(tot, (n, ex, un, ov, other), strict=True)]
    print(f"| all | {tot[0]} | {tot[1]} | {tot[2]} | {tot[3]} | | {tot[4]} |\n")
    print("| target | goal | measured | met |")
    print("|---|---|---|---|")
    met = "yes" if tot[1] == tot[0] else "no"
    print(f"| lost exact (baseline: 243 of 270) | every trial | {tot[1]} of {tot[0]} | {met} |")
    met = "yes" if not tot[4] else "no"
    print(f"| rows the firmware's, in order | every trial | {tot[0] - tot[4]} of {tot[0]} | {met} |")


if __name__ == "__main__":
    main()
