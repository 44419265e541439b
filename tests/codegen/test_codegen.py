"""Generated C, through cffi, in lockstep with the float64 reference (accelnav.estimate.kf).

Every state at every step must lie within the generator's stated bound, and
after the first second within 1e-3 of the reference's own standard deviation;
the overflow counters stay zero. Both fixed-point forms, two sample rates, six
simulated scenarios (including the +-50 g stress profile and rail-clipped
shocks), both axes. Plus: byte-identical regeneration, the banner, strict
compiles (host, sanitizers, Cortex-M0/M3) and the float32 variant.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest
from support.codegen_lockstep import SIGMA_FRACTION, blind_schedule, built, check_against_bound, plan

from accelnav.codegen.emit_c import _schedule_for, emit
from accelnav.codegen.ranges import plan_axis
from accelnav.estimate.kf import run_filter
from accelnav.hil_sim.targets.harness import STRICT, AxisRunner, build
from accelnav.model.design import axis_design
from accelnav.model.load import load_model, loads_model

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")

SCENARIOS = ("stationary", "stop_and_go", "sinusoid", "vehicle", "stress", "shock")
DURATION = {100.0: 30.0, 1000.0: 3.0}


def model_at(rate: float):
    base = load_model()
    if rate == base.rate_hz:
        return base
    text = open(base.source).read().replace("rate_hz = 100.0", f"rate_hz = {rate}")
    return loads_model(text, source=f"adxl250_default@{rate:g}Hz")


_REF: dict = {}


@pytest.fixture(scope="session")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("codegen")


def reference(model, scenario, axis):
    key = (model.sha256, scenario, axis)
    if key not in _REF:
        run = sensor.simulate(model, scenario, DURATION[model.rate_hz], seed=11)
        d = axis_design(model, axis)
        valid = ~run.clipped[:, axis]
        ref = run_filter(d, run.accel[:, axis], valid=valid)
        sig = np.sqrt(np.einsum("kii->ki", ref.P_post))
        _REF[key] = (run, d, valid, ref, sig)
    return _REF[key]


@pytest.mark.parametrize("rate", [100.0, 1000.0])
@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_lockstep(rate, form, scenario, workdir):
    model = model_at(rate)
    files, mod = built(model, form, workdir)
    for axis in range(len(model.axes)):
        run, d, valid, ref, sig = reference(model, scenario, axis)
        p, sched = plan(model, axis, form)
        res = AxisRunner(mod, files["accelnav.json"], axis).run(code=run.code[:, axis])
        assert res["overflow"] == 0
        assert np.array_equal(res["valid"], valid), "the C and the reference disagree on which samples to skip"
        x_ref = ref.x_post  # always the float64 Kalman filter with the same skips
        err = np.abs(res["x"] - x_ref)
        check_against_bound(p, sched, run.code[:, axis], run.accel[:, axis], valid, x_ref, res["x"], f"axis {axis}")
        k1 = int(model.rate_hz)
        ratio = err[k1:] / sig[k1:]
        worst = np.unravel_index(np.argmax(ratio), ratio.shape)
        assert ratio.max() <= SIGMA_FRACTION, (
            f"axis {axis}: state {worst[1]} at sample {worst[0] + k1}: {ratio.max():.3g} sigma"
        )


def test_duty_cycle_part(workdir):
    """A duty-cycle model: T1/T2 conversion without a division, bad captures skipped."""
    text = open(load_model().source).read()
    text = text.replace('kind = "analog" ', 'kind = "duty_cycle"').replace("range_g = 50.0", "range_g = 4.0")
    a = text.index("[sensor.analog]")
    b = text.index("[sampling]")
    text = (
        text[:a]
        + "[sensor.duty_cycle]\ntimer_clock_hz = 1.0e6\nt2_period_s = 0.005\nzero_g_duty = 0.5\nduty_per_g = 0.125\n\n"
        + text[b:]
    )
    text = text.replace("zero_g_v = 2.501\n", "")
    text = text.replace("max_run_s = 3600.0", "max_run_s = 600.0")
    model = loads_model(text, source="duty.toml")
    files, mod = built(model, "covariance", workdir)
    run = sensor.simulate(model, "stop_and_go", 20.0, seed=3)
    d = axis_design(model, 0)
    valid = ~run.clipped[:, 0]
    ref = run_filter(d, run.accel[:, 0], valid=valid)
    sig = np.sqrt(np.einsum("kii->ki", ref.P_post))
    res = AxisRunner(mod, files["accelnav.json"], 0).run(t1=run.t1[:, 0], t2=run.t2[:, 0])
    assert res["overflow"] == 0
    assert np.array_equal(res["valid"], valid)
    err = np.abs(res["x"] - ref.x_post)
    check_against_bound(
        plan(model, 0, "covariance")[0], None, None, run.accel[:, 0], valid, ref.x_post, res["x"], "duty"
    )
    assert (err[100:] / sig[100:]).max() <= SIGMA_FRACTION


@pytest.mark.parametrize("model_file", ["adxl250_default.toml", "adxl202_duty.toml"])
def test_gain_schedule_generated_for_inputs_that_skip(model_file, tmp_path, capsys):
    """Every input kind can skip samples (rails, bad captures); the gain-schedule form follows them
    (codegen.follow), so the generator takes it for both, CLI included."""
    from conftest import MODELS

    from accelnav.cli import main

    model = load_model(MODELS / model_file)
    files = emit(model, form="gain_schedule")
    assert "_follow(" in files["accelnav.c"]
    assert main(["codegen", model.source, "--form", "gain_schedule", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "accelnav.c").read_text() == files["accelnav.c"]


def test_gain_schedule_deviation_twin_is_bit_exact_and_the_check_catches_a_blind_schedule(workdir, tmp_path):
    """On rail-clipped shocks: the C's deviation block equals its integer twin (codegen.follow.Follow,
    from which the stated bound takes the C's gains) after every sample; and the same C with the
    skip-following cut out (a time-indexed schedule that ignores skips) leaves the stated bound."""
    from accelnav.codegen.follow import DEV, Follow, thresholds

    model = model_at(100.0)
    files, mod = built(model, "gain_schedule", workdir)
    run, d, valid, ref, sig = reference(model, "shock", 0)
    assert not valid.all()
    p, sched = plan(model, 0, "gain_schedule")
    lib, ffi = mod.lib, mod.ffi
    s = ffi.new("accelnav_x_t *")
    lib.accelnav_x_init(s)
    twin = Follow(p, thresholds(sched))
    G = sched.gains_int(len(valid))
    followed = 0
    for k, c in enumerate(run.code[:, 0].tolist()):
        if twin.dev or not valid[k]:
            twin.step(k, bool(valid[k]), [int(x) for x in G[k]])
        lib.accelnav_x_step(s, c)
        assert bool(s.k >> 31) == twin.dev, f"sample {k}: the C and its twin disagree on following a skip"
        if twin.dev:
            followed += 1
            got = [getattr(s, nm) for nm in DEV]
            assert got == [twin.D[nm] for nm in DEV], f"sample {k}: deviation block {got}"
    assert followed > (~valid).sum() and s.overflow == 0 == twin.overflow
    blind = build(blind_schedule(files), tmp_path)
    res = AxisRunner(blind, files["accelnav.json"], 0).run(code=run.code[:, 0])
    with pytest.raises(AssertionError, match="of the stated bound"):
        check_against_bound(p, sched, run.code[:, 0], run.accel[:, 0], valid, ref.x_post, res["x"], "blind")


def test_skip_table(workdir):
    """Edge inputs: the rails and the codes next to them; a skipped sample predicts only."""
    model = load_model()
    files, mod = built(model, "covariance", workdir)
    lib, ffi = mod.lib, mod.ffi
    z = ffi.new("int32_t *")
    full = 2**model.sensor.analog.adc_bits - 1
    for code, ok in ((0, False), (1, True), (full - 1, True), (full, False), (-5, False), (full + 10, False)):
        assert lib.accelnav_x_convert(code, z) is ok, code
    s = ffi.new("accelnav_x_t *")
    lib.accelnav_x_init(s)
    lib.accelnav_x_step(s, 2048)
    before = (s.a, s.e, s.k)
    assert lib.accelnav_x_step(s, 0) is False
    # predict only: a is a random walk, unchanged; k counts samples in bits 1..31
    assert s.a == before[0] and s.k >> 1 == (before[2] >> 1) + 1


def test_gain_schedule_count_restarts_past_2_31_without_leaving_the_schedule(workdir):
    """k's sign bit is the gain schedule's "following a skip" flag: a count that reaches 2^31 on the
    schedule restarts at 2^30 (past the schedule's end) in the out-of-line step, with the flag clear and
    the same integers as a run whose count is simply below it; a skipped sample still sets the flag."""
    model = load_model()
    files, mod = built(model, "gain_schedule", workdir)
    lib, ffi = mod.lib, mod.ffi
    run = sensor.simulate(model, "vehicle", 1.0, seed=3)
    codes = [int(c) for c in run.code[:, 0]]
    a, b = ffi.new("accelnav_x_t *"), ffi.new("accelnav_x_t *")
    lib.accelnav_x_init(a)
    for c in codes[:50]:
        assert lib.accelnav_x_step(a, c)
    ffi.memmove(b, a, ffi.sizeof("accelnav_x_t"))
    # a: 2^31 - 1 -> 2^31 (flag bit set by the count) -> restarted at 2^30, + 1 -> 2^30 + 2
    a.k, b.k = 2**31 - 1, 2**30 - 1
    for c in codes[50:53]:
        assert lib.accelnav_x_step(a, c) and lib.accelnav_x_step(b, c)
    assert a.k == 2**30 + 2 and b.k == 2**30 + 2, (hex(a.k), hex(b.k))
    assert bytes(ffi.buffer(a)) == bytes(ffi.buffer(b)), "the restart changed more than the count"
    assert lib.accelnav_x_step(a, 0) is False and a.k >> 31 == 1 and a.k & (2**31 - 1) == 2**30 + 3


def test_regeneration_is_byte_identical_and_bannered():
    model = load_model()
    for form in ("covariance", "gain_schedule"):
        a = emit(model, form=form)
        b = emit(load_model(), form=form)
        assert a == b
        for name in ("accelnav.h", "accelnav.c"):
            assert model.sha256 in a[name].splitlines()[2]
            assert "accelnav codegen 0.1.0" in a[name].splitlines()[1]
            assert "DO NOT EDIT" in a[name]
    f32 = emit(model, arith="float32", prefix="accelnav_f32")
    assert f32 == emit(model, arith="float32", prefix="accelnav_f32")


def test_no_float_no_division_in_fixed_point():
    src = emit(load_model())["accelnav.c"]
    body = re.sub(r"/\*.*?\*/", "", src[src.index("#endif") :], flags=re.S)
    for bad in ("float", "double", " / ", "malloc", "#include <"):
        assert bad not in body, bad


def _driver(files, prefix, codes, axis_name="x", ef="e"):
    """A stand-alone C program that runs one axis over `codes` and prints the raw states."""
    arr = ", ".join(str(int(c)) for c in codes)
    T = f"{prefix}_{axis_name}"
    return f"""#include <stdio.h>
#include "{prefix}.h"
static const int32_t codes[] = {{{arr}}};
int main(void)
{{
    {T}_t s;
    size_t k;
    {T}_init(&s);
    for (k = 0; k < sizeof codes / sizeof codes[0]; ++k) {{
        {T}_step(&s, codes[k]);
        printf("%lld %lld %ld %lld\\n", (long long)s.r, (long long)s.v, (long)s.a, (long long)s.{ef});
    }}
    printf("overflow %lu\\n", (unsigned long)s.overflow);
    return 0;
}}
"""


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_sanitizers_bit_identical(form, workdir, tmp_path):
    """-fsanitize=undefined,address build runs the stress and shock data clean, bit-identical to the cffi run."""
    model = load_model()
    files, mod = built(model, form, workdir)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    for scenario in ("stress", "shock"):
        run = sensor.simulate(model, scenario, 10.0, seed=5)
        ef = "eb" if form == "gain_schedule" else "e"  # the gain schedule's eps state (emit_c._gs_defines)
        (tmp_path / "drv.c").write_text(_driver(files, "accelnav", run.code[:, 0], ef=ef))
        exe = tmp_path / "drv"
        flags = [*STRICT, "-fsanitize=undefined,address", "-fno-sanitize-recover=all", "-g"]
        subprocess.run(
            ["gcc", *flags, str(tmp_path / "drv.c"), str(tmp_path / "accelnav.c"), "-o", str(exe)],
            check=True,
            capture_output=True,
            text=True,
        )
        out = subprocess.run([str(exe)], check=True, capture_output=True, text=True)
        assert out.stderr == ""
        rows = out.stdout.splitlines()
        assert rows[-1] == "overflow 0"
        r = AxisRunner(mod, files["accelnav.json"], 0)
        step = mod.lib.accelnav_x_step
        for k, c in enumerate(run.code[:, 0]):
            step(r.state, int(c))
            s = r.state
            assert rows[k] == f"{s.r} {s.v} {s.a} {getattr(s, ef)}", f"sample {k}"


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None, reason="arm-none-eabi-gcc not installed")
@pytest.mark.parametrize("cpu", ["cortex-m0", "cortex-m3"])
def test_cross_compiles(cpu, tmp_path):
    model = load_model()
    for form, arith in (("covariance", "fixed"), ("gain_schedule", "fixed"), ("covariance", "float32")):
        files = emit(model, form=form, arith=arith)
        for name, text in files.items():
            (tmp_path / name).write_text(text)
        subprocess.run(
            [
                "arm-none-eabi-gcc",
                f"-mcpu={cpu}",
                "-mthumb",
                "-ffreestanding",
                *STRICT,
                "-c",
                str(tmp_path / "accelnav.c"),
                "-o",
                str(tmp_path / "accelnav.o"),
            ],
            check=True,
        )


def test_float32_variant(workdir):
    """The float32 variant from the same generator tracks the reference to ~1e-3 sigma (float32 epsilon)."""
    model = load_model()
    files = emit(model, arith="float32", prefix="accelnav_f32")
    mod = build(files, workdir, prefix="accelnav_f32")
    run, d, valid, ref, sig = reference(model, "stress", 0)
    res = AxisRunner(mod, files["accelnav_f32.json"], 0, prefix="accelnav_f32").run(code=run.code[:, 0])
    assert np.array_equal(res["valid"], valid)
    ratio = np.abs(res["x"] - ref.x_post)[100:] / sig[100:]
    assert ratio.max() < 1e-2


def test_cli_writes_files_and_report(tmp_path, capsys):
    from accelnav.cli import main

    model = load_model()
    assert main(["codegen", model.source, "--out", str(tmp_path), "--report"]) == 0
    out = capsys.readouterr().out
    names = {"accelnav.c", "accelnav.h", "accelnav.json", "acnframe.c", "acnframe.h", "acnframe.json"}
    assert {p.name for p in tmp_path.iterdir()} == names  # the filter and the frames: what the firmware needs
    for needle in ("Q16.47", "predicted error bound", "RAM", "resolution"):
        assert needle in out


MUTATIONS = {
    # the input offset one LSB off: a bias of one LSB of z, twice what the conversion may round
    "OFFSET +1 LSB": (r"(#define ACCELNAV_X_OFFSET INT32_C\()(-?\d+)", lambda m: f"{m.group(1)}{int(m.group(2)) + 1}"),
    # K_a y shifted one bit too far (K_a read in the wrong format); the covariance form adds c_a w
    "Ka shift +1": (
        r"((?:acn_add_round\(a, |ACN_RSHR\()acn_mul\((?:Ka, y|ca, w)\), |acn_mul_rshr32\(ca, w, )(\d+)",
        lambda m: f"{m.group(1)}{int(m.group(2)) + 1}",
    ),
    # eps_bar off by 1 %: the bias's fixed point
    "EBAR +1 %": (
        r"(#define ACCELNAV_X_EBAR INT32_C\()(-?\d+)",
        lambda m: f"{m.group(1)}{int(int(m.group(2)) * 1.01)}",
    ),
}


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
@pytest.mark.parametrize("mutation", sorted(MUTATIONS))
def test_mutations_break_the_lockstep(form, mutation, workdir):
    """The stated bound is tight enough to catch a constant one LSB off where one LSB matters, or a
    product read in the wrong format. (A wrong rounding direction, at most one LSB a step, stays
    within it: see the note in codegen/bounds.py.)"""
    model = load_model()
    files = dict(built(model, form, workdir)[0])
    pat, rep = MUTATIONS[mutation]
    src, n = re.subn(pat, rep, files["accelnav.c"], count=1)
    assert n == 1, mutation
    files["accelnav.c"] = src
    mod = build(files, workdir)
    run, d, valid, ref, sig = reference(model, "vehicle", 0)
    p, sched = plan(model, 0, form)
    res = AxisRunner(mod, files["accelnav.json"], 0).run(code=run.code[:, 0])
    with pytest.raises(AssertionError):
        check_against_bound(p, sched, run.code[:, 0], run.accel[:, 0], valid, ref.x_post, res["x"], mutation)


def test_unclamped_predict_sums_fit_any_state(workdir):
    """The predict sums emitted without a clamp (codegen.ranges._predict_sat_free) stay in int32 for
    the carried entries at the ends of their words: c_e' keeps the sign and size of phi c_e."""
    model = load_model()
    files, mod = built(model, "covariance", workdir)
    p, _ = plan(model, 0, "covariance")
    assert "ce" in p.sat_free
    phi = p.design.phi
    for x in (2**31 - 1, -(2**31)):
        s = mod.ffi.new("accelnav_x_t *")
        mod.lib.accelnav_x_init(s)
        s.k = 2  # one sample done, the block in its coarse formats
        s.ce = x
        s.Pae = x
        mod.lib.accelnav_x_skip(s)
        # c_e' = phi^2 c_e + phi (1 - phi) P_ae + Q_ee, P_ae and c_e in one format here
        want = phi * x + p.consts["Qee"][0] * 2.0 ** p.f("ce")
        assert p.f("Pae") == p.f("ce")
        assert abs(s.ce - want) <= 4, (x, s.ce, want)


def test_covariance_reciprocal_within_its_contract(tmp_path):
    """acn_recip_t (table start, two Newton-Raphson steps: the covariance form's 1/S) keeps acn_recip's
    contract, 1/d = x 2^(n - 62) to a relative 2^-28, over the whole uint32 range: every power of two
    and its neighbours, each table interval's ends and middle, and a seeded random sweep."""
    from accelnav.codegen.emit_c import RECIP_TABLE_BITS, recip_helpers, runtime_text
    from accelnav.native.cbuild import build_module

    src = "#include <stdint.h>\n#include <stdbool.h>\n#include <stddef.h>\n" + runtime_text() + recip_helpers()
    src += "uint32_t t_recip(uint32_t d, int *n) { return acn_recip_t(d, n); }\n"
    mod = build_module(
        "acn_recip_test", "uint32_t t_recip(uint32_t d, int *n);", {"r.c": src}, main="r.c", workdir=tmp_path
    )
    ds = {1, 2**32 - 1}
    for k in range(32):
        ds |= {2**k, 2**k + 1, max(1, 2**k - 1)}
    step = 2 ** (31 - RECIP_TABLE_BITS)  # the table's intervals of D = d 2^n in [2^31, 2^32)
    for i in range(2**RECIP_TABLE_BITS):
        lo = 2**31 + i * step
        ds |= {lo, lo + step // 2, lo + step - 1}
    ds |= {int(x) for x in np.random.default_rng(5).integers(1, 2**32, 20000, dtype=np.uint64)}
    n = mod.ffi.new("int *")
    worst = 0.0
    for d in sorted(ds):
        x = mod.lib.t_recip(d, n)
        assert n[0] == 32 - d.bit_length()
        worst = max(worst, abs(x * d * 2.0 ** (n[0] - 62) - 1.0))
    assert worst <= 2.0**-28, f"relative error {worst:.3g} > 2^-28"


SHOCK_1KHZ_SIGMA = 2e-4  # issue #12: a 5x margin to 1e-3; reached 8.8e-5 (seed 11); main's generator 2.7e-4


@pytest.mark.parametrize(("scenario", "seed"), [("shock", 9), ("shock", 11), ("stress", 13)])
def test_covariance_1khz_shock_margin(scenario, seed, workdir):
    """The covariance form at 1 kHz against the float64 Kalman filter with the same skips: every state
    of both axes within SHOCK_1KHZ_SIGMA of the filter's sigma after 1 s, the 5x margin to the 1e-3
    criterion that issue #12 asks, on rail-clipped shock data (c_r, c_v, c_a in their fine formats away
    from gaps, codegen.ranges._plan_fine) and on stress data (eps at 2.06e-4 sigma while c_e kept the
    format its prior sets; 3.0e-5 with c_e in a fine format too); bench/speed/bench_cov_margin.py for every
    scenario."""
    model = model_at(1000.0)
    run = sensor.simulate(model, scenario, 3.0, seed=seed)
    assert run.clipped.any() == (scenario == "shock")
    _within_sigma_of_float64(model, "covariance", run, workdir, SHOCK_1KHZ_SIGMA)


def _within_sigma_of_float64(model, form, run, workdir, limit: float, bound: bool = False) -> None:
    """Every state of every axis of the generated C on ``run``, against the float64 Kalman filter with the
    same skips: below ``limit`` of the filter's sigma after 1 s (and within the stated bound at every step
    when ``bound``), no saturation."""
    files, mod = built(model, form, workdir)
    k1 = int(model.rate_hz)
    for axis in range(len(model.axes)):
        valid = ~run.clipped[:, axis]
        ref = run_filter(axis_design(model, axis), run.accel[:, axis], valid=valid)
        sig = np.sqrt(np.einsum("kii->ki", ref.P_post))
        res = AxisRunner(mod, files["accelnav.json"], axis).run(code=run.code[:, axis])
        assert res["overflow"] == 0
        if bound:
            p, sched = plan(model, axis, form)
            check_against_bound(p, sched, run.code[:, axis], run.accel[:, axis], valid, ref.x_post, res["x"], form)
        ratio = np.abs(res["x"] - ref.x_post)[k1:] / sig[k1:]
        worst = np.unravel_index(np.argmax(ratio), ratio.shape)
        assert ratio.max() <= limit, f"axis {axis}: state {worst[1]} at sample {worst[0] + k1}: {ratio.max():.3g} sigma"


@pytest.mark.parametrize(("rate", "seed"), [(100.0, 2), (100.0, 13), (1000.0, 5), (1000.0, 13)])
def test_gain_schedule_after_skips_over_seeds(rate, seed, workdir):
    """The gain schedule on rail-clipped shock data, on the seeds where main's generator left the float64
    Kalman filter (test_lockstep runs seed 11 only): within the stated bound at every step and within
    SIGMA_FRACTION of the filter's sigma after 1 s. Before codegen.follow's return thresholds followed the
    schedule's own tolerance at each sample and its deviation entries carried a zoom, 100 Hz seeds 2 and
    13 gave r 1.6e-3 and u 2.1e-3 sigma (a gap early in the run, a return to the schedule with K_r still
    ~20 % off), and 1 kHz seed 5 r 1.3e-3, seed 13 a 1.2e-3 (dK resolved to ~1e-3 of K_r: the C never
    returned to the schedule); bench/speed/bench_cov_margin.py --form gain_schedule for every seed and scenario."""
    model = model_at(rate)
    run = sensor.simulate(model, "shock", 10.0 if rate == 100.0 else 3.0, seed=seed)
    assert run.clipped.any()
    _within_sigma_of_float64(model, "gain_schedule", run, workdir, SIGMA_FRACTION, bound=True)


def test_covariance_fine_formats_follow_a_gap(workdir):
    """c_r, c_v, c_a, c_e are carried in their fine formats away from gaps (bit 0 of k) and in the coarse
    ones from a skipped sample on, back to the fine ones once they are within their switch levels (the
    first samples too, until c_e has come down from the prior's): at each stage the carried entries,
    read in the format of their mode, are the float64 Riccati's posterior c = K R to a few parts in a
    million, and nothing saturates."""
    model = model_at(1000.0)
    files, mod = built(model, "covariance", workdir)
    p, _ = plan(model, 0, "covariance")
    gap = p.gap
    n = 1000 + gap + 200
    valid = np.ones(n, dtype=bool)
    valid[1000 : 1000 + gap] = False
    from accelnav.codegen.gains import riccati

    g = riccati(p.design, n, valid)
    cs = np.array([1.0, p.design.Ts, 1.0, 1.0])
    s = mod.ffi.new("accelnav_x_t *")
    mod.lib.accelnav_x_init(s)
    modes = []
    since = 0  # samples since the last switch to fine
    for k in range(n):
        if valid[k]:
            mod.lib.accelnav_x_update(s, 0)
        else:
            mod.lib.accelnav_x_skip(s)
        fine = bool(s.k & 1)
        since = since + 1 if fine and modes and modes[-1] else 0
        modes.append(fine)
        if valid[k]:
            want = g.K[k] * cs * p.design.R  # posterior c = K R
            for i, nm in enumerate(("cr", "cv", "ca", "ce")):
                f = p.vars[nm + "_f" if fine else nm].fmt
                got = getattr(s, nm) * f.lsb
                tol = 1e-5 * abs(want[i]) + 64 * f.lsb
                if nm == "ce" and since < 100:  # c_e passes zero: what it carries from the coarse stage,
                    tol += p.vars["ce"].fmt.lsb  # below one coarse LSB, decays with the updates
                assert abs(got - want[i]) <= tol, (k, nm, fine, got, want[i])
    modes = np.array(modes)
    assert s.k >> 1 == n and s.overflow == 0
    first = int(np.argmax(modes))
    assert first < 100 and modes[first:1000].all(), f"fine from sample {first} on"
    assert not modes[1000 : 1000 + gap].any(), "coarse through the gap"
    back = 1000 + gap + int(np.argmax(modes[1000 + gap :]))
    assert modes[back:].all() and back < 1000 + gap + 100, back


@pytest.mark.parametrize("rate", [100.0, 1000.0])
def test_covariance_random_skip_bursts(rate, workdir):
    """Bursts of skipped samples of random lengths (up to 0.4 s, beyond the 0.25 s the ranges analyse)
    between valid runs of random lengths, so that the block switches between its coarse and fine
    formats hundreds of times: nothing saturates and every state stays within 1e-3 of the float64
    filter's sigma (same skips) after 1 s."""
    model = model_at(rate)
    files, mod = built(model, "covariance", workdir)
    run = sensor.simulate(model, "vehicle", 10.0, seed=4)
    rng = np.random.default_rng(7)
    code = run.code[:, 0].copy()
    valid = ~run.clipped[:, 0]
    k, n = 0, len(code)
    while k < n:
        g = int(rng.integers(1, int(0.4 * rate) + 1)) if rng.random() < 0.5 else int(rng.integers(1, 4))
        code[k : k + g] = 0
        valid[k : k + g] = False
        k += g + int(rng.integers(1, 300))
    ref = run_filter(axis_design(model, 0), run.accel[:, 0], valid=valid)
    sig = np.sqrt(np.einsum("kii->ki", ref.P_post))
    res = AxisRunner(mod, files["accelnav.json"], 0).run(code=code)
    assert (res["valid"] == valid).all() and res["overflow"] == 0
    k1 = int(rate)
    ratio = np.abs(res["x"] - ref.x_post)[k1:] / sig[k1:]
    assert ratio.max() < 1e-3, ratio.max(0)


def test_gain_schedule_built_window_by_window():
    """The schedule over a declared run is built from a window of gains that moves forward: the same
    integers as from the whole run at once (here a 1024-sample window over 60 s at 100 Hz), and at
    1 kHz over the declared hour (3.6e6 samples) its traced memory stays far below what the whole
    run's per-sample arrays take (~30 B per sample per array, 2 GB in all before)."""
    import tracemalloc

    from accelnav.codegen import gains
    from accelnav.codegen.emit_c import SCHEDULE_REL_TOL
    from accelnav.codegen.gains import riccati, schedule, schedule_of

    model = load_model()
    p = plan_axis(model, 0, "gain_schedule")
    fm = tuple(p.vars["K" + n].fmt for n in "rvae")
    n = 6000
    whole = schedule(
        np.asarray(riccati(p.design, n).K) * np.array([1.0, p.design.Ts, 1.0, 1.0]), fm, SCHEDULE_REL_TOL, ramp=1000
    )
    win = schedule_of(p.design, n, fm, SCHEDULE_REL_TOL, ramp=1000, window=1024)
    assert win.n_segments > 20 and (win.lengths, win.slopes, win.start) == (whole.lengths, whole.slopes, whole.start)
    assert np.array_equal(win.gains_int(n), whole.gains_int(n))
    assert np.array_equal(win.errors(n), whole.errors(n))

    fast = model_at(1000.0)
    p = plan_axis(fast, 0, "gain_schedule")
    gains._SCHEDULES.clear()  # built here, not served from the cache
    tracemalloc.start()
    sched = _schedule_for(p)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert sched.n == p.n_run == 3_600_000
    assert peak < 150e6, f"{peak / 1e6:.0f} MB traced while building the 1 kHz schedule"


def test_gain_schedule_report_bound_in_pieces():
    """The report's data-free bound of the gain-schedule form over a long run is the same recursion
    taken a chunk at a time (memory independent of the run): equal to the whole run's, sample for
    sample, at the rows asked for."""
    from accelnav.codegen.bounds import _schedule_bound_rows, error_bound

    p, sched = plan(load_model(), 0, "gain_schedule")
    n = 20_000
    rows = [0, 99, 4_095, 4_096, 12_345, n - 1]
    whole = error_bound(p, n, sched)[rows]
    assert np.array_equal(_schedule_bound_rows(p, n, rows, sched, chunk=4_096), whole)
