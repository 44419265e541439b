"""One absurd sample in a stationary recording (issue 21, item 12): named by its line and column, not
reported as the edited model's bad c1 after a fit it wrecked."""

from __future__ import annotations

import numpy as np

from accelnav.cli import main


def test_a_sample_beyond_the_sensor_range_is_named(tmp_path, capsys):
    rng = np.random.default_rng(4)
    n = 12_000  # 120 s at 100 Hz: long enough for the fit
    y = 1.0 + 0.001 * rng.standard_normal(n)
    y[5000] = 1e30
    path = tmp_path / "rest.csv"
    rows = [f"{k / 100:.2f},{0.001 * rng.standard_normal():.6f},{v:.6g}" for k, v in enumerate(y)]
    path.write_text("t,acc_x_g,acc_y_g\n" + "\n".join(rows) + "\n")
    status = main(["fit-bias", str(path), "--out", str(tmp_path / "m.toml")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert "axis 'y': sample 5000 (line 5002), column 'acc_y_g': 9.80665e+30 m/s^2 is beyond the range" in err, err
    assert "a glitch, or the wrong unit" in err and "c1" not in err
    assert not (tmp_path / "m.toml").exists()
