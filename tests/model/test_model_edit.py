"""The model writer and the edits (model.edit): dump_model round-trips every field of every shipped model and
odd strings, and every edit is checked by the loader (moved here from the fit-bias command's tests)."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import MODELS

from accelnav.model.edit import dump_model, revalidate, with_axis_bias, with_noise
from accelnav.model.load import ModelError, load_model, loads_model


def _same_fields(a, b) -> list[str]:
    skip = {"source", "sha256", "text"}
    return [f.name for f in dataclasses.fields(a) if f.name not in skip and getattr(a, f.name) != getattr(b, f.name)]


@pytest.mark.parametrize("path", sorted(MODELS.glob("*.toml")), ids=lambda p: p.name)
def test_dump_model_round_trips_every_field(path):
    m = load_model(path)
    text = dump_model(m)
    back = loads_model(text)
    assert _same_fields(m, back) == []
    assert dump_model(back) == text  # canonical: a second pass changes nothing


def test_dump_model_keeps_odd_strings_and_overrides(default_model):
    name = 'quote " backslash \\ tab \t newline \n del \x7f unicode µ'
    m = dataclasses.replace(default_model, description=name)
    m = with_axis_bias(m, "z", -1e-17, -9.80665, 12345.678901234567)
    ax = dataclasses.replace(m.axes[0], sensitivity=0.0381, zero_g=2.4999)
    m = dataclasses.replace(m, axes=(ax, *m.axes[1:]))
    back = loads_model(dump_model(m, header="first line\nsecond line"))
    assert _same_fields(m, back) == []
    assert back.axis("z").T == 12345.678901234567 and back.axis("x").zero_g == 2.4999
    assert dump_model(m, header="first line\nsecond line").startswith("# first line\n# second line\n")


def test_edits_are_checked_by_the_loader(default_model):
    m = with_noise(with_axis_bias(default_model, "x", 0.1, 0.2, 30.0), R=0.5, sigma_eps=0.0)
    v = revalidate(m)
    assert v.axis("x").c1 == 0.1 and v.noise.R == 0.5 and v.noise.sigma_eps == 0.0 and v.noise.sigma_n == 1.0
    assert len(v.sha256) == 64 and v.text == dump_model(m)
    four = with_axis_bias(with_axis_bias(default_model, "z", 0, 0, 1.0), "w", 0, 0, 1.0)
    with pytest.raises(ModelError, match="accepted: 1 to 3"):
        revalidate(four)
    with pytest.raises(ModelError, match="full scale"):
        revalidate(with_axis_bias(default_model, "x", 400.0, 200.0, 1.0))
