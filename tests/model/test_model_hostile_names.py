"""Issue 21 items 1 and 6 at the loader: a model is someone else's file, and its strings reach C.

Every name that fails the one rule (accelnav.model.load.name_problem) is refused in one line naming the
file and the key, before any C is generated or compiled; so is a T or max_run_s beyond its physical bound.
"""

from __future__ import annotations

import pytest
from conftest import model_text

from accelnav.cli import main
from accelnav.model.load import MAX_RUN_S, MAX_T_S, ModelError, loads_model, model_name_from, name_problem

NAME = 'name = "adxl250_default"'

HOSTILE_MODEL_NAMES = [
    "x */ __attribute__((constructor)) static void p(void) { } /* y",  # closes the banner comment
    "a\\nb",  # a TOML escape: a newline in the name
    "caf\\u00e9",  # non-ASCII
    'quote \\" here',
    "trigraph ??/",
    "back\\\\slash",
    "slash/star",
    "// line",
    "x" * 65,  # too long
    "",
]


def _one_line_refusal(text: str, key: str) -> str:
    with pytest.raises(ModelError) as e:
        loads_model(text, source="theirs.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"theirs.toml: {key}: "), msg
    return msg


@pytest.mark.parametrize("name", HOSTILE_MODEL_NAMES)
def test_hostile_model_name_refused(name):
    text = model_text().replace(NAME, f'name = "{name}"')
    assert text != model_text()
    msg = _one_line_refusal(text, "model.name")
    assert "accepted:" in msg and msg.isascii()


AXIS_CASES = [
    ([("y", "X")], "axes[1].name", "collides"),  # x and X are one macro (ACCELNAV_X_...)
    ([("y", "x_out")], "axes[1].name", "collides"),  # accelnav_x_out_t would name two types
    ([("x", "ss"), ("y", "\u00df")], "axes[1].name", "C identifier"),  # non-ASCII (folds to ss)
    ([("x", "int")], "axes[0].name", "C keyword"),
    ([("x", "true")], "axes[0].name", "C keyword"),
    ([("x", "x */ int y; /*")], "axes[0].name", "C identifier"),
    ([("x", "_x")], "axes[0].name", "C identifier"),
    ([("x", "a" * 33)], "axes[0].name", "C identifier"),
]


@pytest.mark.parametrize(("renames", "key", "why"), AXIS_CASES)
def test_hostile_axis_names_refused(renames, key, why):
    text = model_text()
    for old, new in renames:
        text = text.replace(f'[[axes]]\nname = "{old}"', f'[[axes]]\nname = "{new}"', 1)
    msg = _one_line_refusal(text, key)
    assert why in msg


def test_safe_names_still_load():
    text = model_text().replace(NAME, 'name = "ADXL250 (bench 2), rev. 3-b"')
    text = text.replace('[[axes]]\nname = "y"', '[[axes]]\nname = "Y_2"', 1)
    m = loads_model(text)
    assert m.name == "ADXL250 (bench 2), rev. 3-b" and [a.name for a in m.axes] == ["x", "Y_2"]


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [("T = 300.0", "T = 1e15", "axes[0].T"), ("max_run_s = 3600.0", "max_run_s = 1e9", "ranges.max_run_s")],
)
def test_loop_lengths_bounded_at_load(old, new, key):
    """T = 1e15 s made codegen spin for hours (phi rounds to 1.0); refused at load with the bound."""
    msg = _one_line_refusal(model_text().replace(old, new), key)
    bound = MAX_T_S if key.endswith(".T") else MAX_RUN_S
    assert f"{bound:g}]" in msg
    # the bounds themselves load
    loads_model(model_text().replace(old, new.split("=")[0] + f"= {bound!r}"))


def test_cli_refuses_hostile_model_before_any_build(tmp_path, monkeypatch, capsys):
    """`accelnav codegen` (which writes C) and the SIL build (which compiles it) stop at the loader."""
    import accelnav.native.cbuild as cbuild
    from accelnav.hil_sim.targets.firmware import build_firmware

    def no_build(*a, **k):
        raise AssertionError("a compiler was invoked for a model the loader must refuse")

    monkeypatch.setattr(cbuild, "build_module", no_build)
    bad = tmp_path / "theirs.toml"
    bad.write_text(model_text().replace(NAME, f'name = "{HOSTILE_MODEL_NAMES[0]}"'))
    with pytest.raises(ModelError, match="model.name"):
        build_firmware(str(bad))
    assert main(["codegen", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "model.name" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text", ["données 2.csv_fit", "*/x/*_fit", "-run;#3\n_fit", "_" * 100, ""])
def test_model_name_from_free_text_passes_the_rule(text):
    """fit-bias names its model after the recording's file, which may hold anything a file name can."""
    name = model_name_from(text)
    assert name_problem("model name", name) is None, name
