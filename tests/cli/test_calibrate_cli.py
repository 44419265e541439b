"""accelnav calibrate as a command: what it prints, the model file it writes (the library's calibration:
equal to accelnav.calibrate's on the same recording and model file) and its one-line refusals. How well the
calibration recovers a part is tested on the library, tests/identify/test_calibrate.py."""

from __future__ import annotations

import numpy as np
from support.calibrate_cases import POSE_S, any_recording, nominal_file, perturbed, save_g_csv, tumble_recording

import accelnav
from accelnav.cli import main
from accelnav.hil_sim.sim.trajectories import TUMBLE_HOLD_S
from accelnav.model.load import G0, load_model


def _axes(model):
    return [(a.name, a.zero_g, a.sensitivity, a.c1, a.c2, a.T) for a in model.axes]


def test_cli_writes_the_calibration(tmp_path, capsys):
    nom, model_path = nominal_file(tmp_path)
    true = perturbed(nom, np.random.default_rng(11))
    run, acc = tumble_recording(nom, true, 11)
    csv = save_g_csv(tmp_path / "tumble.csv", run.t, acc)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(csv), "--model", str(model_path), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "6 still poses" in text and "not identifiable" in text
    assert _axes(load_model(out)) == _axes(accelnav.calibrate(csv, model_path).model)
    assert out.read_text().startswith("# accelnav model written by accelnav calibrate\n")


def _cli_error(args, capsys) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    return err


def test_refusals(tmp_path, capsys):
    nom, model_path = nominal_file(tmp_path)
    run, acc = tumble_recording(nom, nom, 2)

    def write(name, a, t=run.t):
        return str(save_g_csv(tmp_path / name, t, a))

    base = ["--model", str(model_path), "--out", str(tmp_path / "o.toml")]
    # too few poses: only the first three
    n3 = int(3 * POSE_S * nom.rate_hz)
    err = _cli_error(["calibrate", write("short.csv", acc[:n3], run.t[:n3]), *base], capsys)
    assert "found 3 still pose(s), need at least 4" in err
    # a pose that is not still: pose 2 creeps by 20 mg over its hold (slow enough to pass as still per window)
    bad = acc.copy()
    k0, k1 = int(POSE_S * nom.rate_hz), int((POSE_S + TUMBLE_HOLD_S) * nom.rate_hz)
    bad[k0:k1, 1] += np.linspace(0, 0.02 * G0, k1 - k0)
    err = _cli_error(["calibrate", write("creep.csv", bad), *base], capsys)
    assert "is not still" in err and "mg between its halves" in err
    # a tilted pose (30 degrees): not aligned
    tilt = acc.copy()
    tilt[k0:k1, 1] += 0.5 * G0
    err = _cli_error(["calibrate", write("tilt.csv", tilt), *base], capsys)
    assert "not within 0.2 g of an aligned pose" in err and "a 2-axis part cannot use tilted poses" in err
    # y never turned: every pose reads it at 0 g (x up, x down, flat, flat, ...)
    flat_y = acc.copy()
    flat_y[:, 1] = acc[:, 1] - G0 * np.round(acc[:, 1] / G0)
    err = _cli_error(["calibrate", write("noy.csv", flat_y), *base], capsys)
    assert "axis y: every pose reads it at +0 g" in err
    # the model's axes must be in the recording
    only_x = tmp_path / "x.csv"
    np.savetxt(only_x, np.column_stack([run.t, acc[:, 0] / G0]), delimiter=",", header="t_s,acc_x_g", comments="")
    err = _cli_error(["calibrate", str(only_x), *base], capsys)
    assert "missing y" in err


def test_cli_random_poses(tmp_path, capsys):
    nom, model_path = nominal_file(tmp_path, 3)
    true = perturbed(nom, np.random.default_rng(12))
    run, acc = any_recording(nom, true, 12)
    csv = save_g_csv(tmp_path / "any.csv", run.t, acc)
    out = tmp_path / "cal.toml"
    assert main(["calibrate", str(csv), "--model", str(model_path), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "12 still poses" in text and "method: gravity magnitude" in text and "axes x-y: cosine" in text
    assert _axes(load_model(out)) == _axes(accelnav.calibrate(csv, model_path).model)
    assert "method: gravity magnitude" in out.read_text()
    # a 2-axis part: the same kind of recording is refused, saying why and what to do instead
    _, model2 = nominal_file(tmp_path)
    csv2 = save_g_csv(tmp_path / "any2.csv", run.t, acc[:, :2], fmt="%.18e")
    err = _cli_error(["calibrate", str(csv2), "--model", str(model2), "--out", str(out)], capsys)
    assert "a 2-axis part cannot use tilted poses" in err and "x up, x down, y up, y down and flat" in err
