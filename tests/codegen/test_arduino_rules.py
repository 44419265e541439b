"""The Arduino library of `accelnav codegen --arduino` by the ecosystem's rules, without a toolchain.

arduino-lint cannot be installed here (no package of it in the registries this project uses), so its rules
that apply to a generated library are checked directly: the Arduino library specification (1.5 format:
library.properties' required fields and their forms, src/ and examples/ each sketch in a folder of its own
name, keywords.txt's lines, data under extras/), and PlatformIO's manifest schema for library.json (the
required name and version, the types and character sets of the optional fields) and platformio.ini's
project keys. Each rule is also shown to catch a library that breaks it.
"""

from __future__ import annotations

import configparser
import json
import re

import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.codegen.arduino import EXAMPLES, check_publisher, library, reference
from accelnav.model.load import loads_model

WHO = {"maintainer": "Ada Lovelace <ada@example.org>", "url": "https://example.org/accelnav"}
PROPERTIES_REQUIRED = ("name", "version", "author", "maintainer", "sentence", "paragraph", "category", "url",
                       "architectures")  # fmt: skip
CATEGORIES = ("Display", "Communication", "Signal Input/Output", "Sensors", "Device Control", "Timing",
              "Data Storage", "Data Processing", "Other")  # fmt: skip
TOKEN_TYPES = ("KEYWORD1", "KEYWORD2", "KEYWORD3", "LITERAL1", "LITERAL2")
SEMVER = re.compile(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(?:-[0-9A-Za-z.-]+)?(?:\+[0-9A-Za-z.-]+)?")


def _model(ref_v: float = 5.0):
    """The default model on the Uno's 10-bit ADC; ``ref_v`` other than 5: a sensor at that supply, read
    ratiometrically against it on AREF (an ADXL335 on 3.3 V)."""
    text = (MODELS / "adxl250_default.toml").read_text()
    text = re.sub(r"^adc_bits = 12", "adc_bits = 10", text, flags=re.M)
    if ref_v != 5.0:
        for key, value in (("supply_v", ref_v), ("adc_ref_v", ref_v), ("zero_g_v", ref_v / 2),
                           ("sensitivity_v_per_g", 0.038 * ref_v / 5.0)):  # fmt: skip
            text = re.sub(rf"^{key} = .*$", f"{key} = {value:.6g}", text, flags=re.M)
    return loads_model(text, source="uno.toml")


def _properties(text: str) -> dict[str, str]:
    out = {}
    for line in text.splitlines():
        if line.strip() and not line.startswith("#"):
            key, sep, value = line.partition("=")
            assert sep, f"not key=value: {line!r}"
            out[key] = value
    return out


def arduino_problems(files: dict[str, str]) -> list[str]:
    """What arduino-lint's library rules find in a library's files (empty: none)."""
    bad = []
    props = _properties(files.get("library.properties", ""))
    bad += [f"library.properties: no {k}" for k in PROPERTIES_REQUIRED if not props.get(k, "").strip()]
    name = props.get("name", "")
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9 _.-]{0,62}", name) or name.lower().startswith("arduino"):
        bad.append(f"name {name!r}")
    if not SEMVER.fullmatch(props.get("version", "")):
        bad.append(f"version {props.get('version')!r} is not semver")
    if props.get("category") not in CATEGORIES:
        bad.append(f"category {props.get('category')!r}")
    if not re.fullmatch(r"https?://\S+", props.get("url", "")):
        bad.append("url is no http(s) address")
    if props.get("maintainer", "").lower().startswith("arduino"):
        bad.append("maintainer starts with Arduino")
    if props.get("paragraph", "").startswith(props.get("sentence", "\0")):
        bad.append("paragraph repeats the sentence")
    for header in filter(None, props.get("includes", "").split(",")):
        if f"src/{header.strip()}" not in files:
            bad.append(f"includes {header}: not in src/")
    if not any(p.startswith("src/") for p in files):
        bad.append("no src/ folder")
    if any(p.endswith((".c", ".cpp", ".h")) and "/" not in p for p in files):
        bad.append("sources at the root beside src/")
    sketches = [p for p in files if p.endswith(".ino")]
    if not sketches:
        bad.append("no example")
    for p in sketches:
        parts = p.split("/")
        if len(parts) != 3 or parts[0] != "examples" or parts[2] != parts[1] + ".ino":
            bad.append(f"{p}: a sketch sits in examples/NAME/NAME.ino")
    bad += [f"{p}: data at the root (extras/)" for p in files if "/" not in p and p.endswith(".json")
            and p != "library.json"]  # fmt: skip
    for k in ("README.md", "LICENSE", "keywords.txt"):
        if k not in files:
            bad.append(f"no {k}")
    for line in files.get("keywords.txt", "").splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        fields = line.split("\t")
        if not re.fullmatch(r"[A-Za-z_]\w*", fields[0]) or len(fields) < 2 or fields[1] not in TOKEN_TYPES:
            bad.append(f"keywords.txt: {line!r}")
    return bad


def platformio_problems(files: dict[str, str]) -> list[str]:
    """What PlatformIO's manifest schema refuses in library.json, and an example's platformio.ini without its
    keys (empty: none)."""
    bad = []
    try:
        m = json.loads(files["library.json"])
    except (KeyError, ValueError) as e:
        return [f"library.json: {e}"]
    name = m.get("name")
    if not isinstance(name, str) or not 1 <= len(name) <= 100 or re.search(r"[:;/,@<>]", name):
        bad.append(f"name {name!r}")
    version = m.get("version")
    if not isinstance(version, str) or not 1 <= len(version) <= 50 or not SEMVER.fullmatch(version):
        bad.append(f"version {version!r}")
    if not isinstance(m.get("description", ""), str) or not 1 <= len(m.get("description", "x")) <= 1000:
        bad.append("description")
    for key, rule in (("keywords", r"[a-z\d\-+. ]{1,50}"), ("platforms", r"[a-z\d\-_]{1,50}|\*"),
                      ("frameworks", r"[a-z\d\-_]{1,50}|\*")):  # fmt: skip
        items = m.get(key, [])
        if not isinstance(items, list) or not all(isinstance(k, str) and re.fullmatch(rule, k) for k in items):
            bad.append(f"{key} {items!r}")
    if "homepage" in m and not re.fullmatch(r"https?://\S{1,245}", m["homepage"]):
        bad.append("homepage")
    for a in m.get("authors", []):
        if not isinstance(a.get("name"), str) or not 1 <= len(a["name"]) <= 50:
            bad.append(f"author {a!r}")
        if "email" in a and not re.fullmatch(r"[^@\s]+@[^@\s]+\.[^@\s]+", a["email"]):
            bad.append(f"author email {a['email']!r}")
        if "maintainer" in a and not isinstance(a["maintainer"], bool):
            bad.append("author maintainer is no boolean")
    for ex in m.get("examples", []):
        if not re.fullmatch(r"[a-zA-Z\d\-_/]{1,100}", ex.get("name", "")) or not isinstance(ex.get("files"), list):
            bad.append(f"example {ex!r}")
        elif not all(f"{ex['base']}/{f}" in files for f in ex["files"]):
            bad.append(f"example {ex['name']}: files not in the library")
    for header in m.get("headers", []):
        if f"src/{header}" not in files:
            bad.append(f"header {header} not in src/")
    return bad + _ini_problems(files, name)


def _ini_problems(files: dict[str, str], name: str) -> list[str]:
    """An example's platformio.ini: an env with its platform, board and framework, the library in lib_deps."""
    bad = []
    for p, text in files.items():
        if p.endswith("platformio.ini"):
            ini = configparser.ConfigParser()
            ini.read_string(text)
            env = [s for s in ini.sections() if s.startswith("env:")]
            if not env or any(k not in ini[env[0]] for k in ("platform", "board", "framework")):
                bad.append(f"{p}: an env needs platform, board and framework")
            elif name not in ini[env[0]].get("lib_deps", ""):
                bad.append(f"{p}: lib_deps does not name the library")
    return bad


def test_the_library_passes_the_arduino_and_platformio_rules():
    files = library(_model(), **WHO)
    assert arduino_problems(files) == []
    assert platformio_problems(files) == []
    props = _properties(files["library.properties"])
    assert props["maintainer"] == WHO["maintainer"] and props["url"] == WHO["url"]
    assert props["includes"] == "AccelNav.h" and props["architectures"] == "avr"
    assert {f"examples/{e}/{e}.ino" for e in EXAMPLES} <= set(files)
    assert {"extras/acnframe.json", "extras/accelnav.json"} <= set(files)
    assert json.loads(files["library.json"])["authors"] == [{"name": "Ada Lovelace", "maintainer": True,
                                                             "email": "ada@example.org"}]  # fmt: skip


@pytest.mark.parametrize(
    ("path", "change", "found"),
    [
        ("library.properties", lambda t: t.replace("url=https://example.org/accelnav", "url="), "no url"),
        ("library.properties", lambda t: t.replace("version=0.1.0", "version=0.1"), "not semver"),
        ("library.properties", lambda t: t.replace("category=Sensors", "category=Sensor"), "category"),
        ("library.properties", lambda t: t.replace("includes=AccelNav.h", "includes=accelnav_x.h"), "includes"),
        ("keywords.txt", lambda t: t + "AccelNav KEYWORD1\n", "keywords.txt"),
        ("keywords.txt", None, "no keywords.txt"),
        ("LICENSE", None, "no LICENSE"),
    ],
)
def test_the_arduino_rules_catch_a_library_that_breaks_them(path, change, found):
    files = library(_model(), **WHO)
    if change is None:
        del files[path]
    else:
        files[path] = change(files[path])
    assert any(found in p for p in arduino_problems(files)), arduino_problems(files)


def test_the_arduino_rules_catch_a_misplaced_sketch_or_data():
    files = library(_model(), **WHO)
    files["acnframe.json"] = files.pop("extras/acnframe.json")
    files["examples/AccelnavStream/Other.ino"] = files.pop("examples/AccelnavStream/AccelnavStream.ino")
    found = " ".join(arduino_problems(files))
    assert "acnframe.json: data at the root" in found and "Other.ino: a sketch sits in" in found


@pytest.mark.parametrize(
    ("key", "value", "found"),
    [("name", "accel/nav", "name"), ("version", "1", "version"), ("keywords", ["Kalman"], "keywords"),
     ("platforms", "atmelavr", "platforms"), ("authors", [{"name": "x" * 51}], "author")],
)  # fmt: skip
def test_the_platformio_rules_catch_a_manifest_that_breaks_them(key, value, found):
    files = library(_model(), **WHO)
    m = json.loads(files["library.json"])
    m[key] = value
    files["library.json"] = json.dumps(m)
    assert any(p.startswith(found) for p in platformio_problems(files)), platformio_problems(files)


def test_platformio_ini_needs_its_keys():
    files = library(_model(), **WHO)
    ini = "examples/AccelnavPlotter/platformio.ini"
    files[ini] = files[ini].replace("board = uno\n", "")
    assert platformio_problems(files) == [f"{ini}: an env needs platform, board and framework"]


def test_the_reference_follows_the_models_adc_ref_v():
    assert reference(_model(5.0))[0] == "DEFAULT"
    assert reference(_model(1.1))[0] == "INTERNAL"
    aref, wiring = reference(_model(3.3))
    assert aref == "EXTERNAL" and "wire AREF to a 3.3 V source" in wiring
    files = library(_model(3.3), **WHO)
    assert "#define ACN_AREF EXTERNAL\n" in files["src/acn_model.h"]
    assert "wire AREF to a 3.3 V source" in files["README.md"]
    assert "analogReference(ACN_AREF);" in files["src/AccelNav.cpp"]
    assert "#define ACN_AREF DEFAULT\n" in library(_model(), **WHO)["src/acn_model.h"]


def test_a_reference_above_the_supply_is_refused_in_one_line(tmp_path, capsys):
    text = (MODELS / "adxl250_default.toml").read_text().replace("adc_bits = 12", "adc_bits = 10")
    text = text.replace("supply_v = 5.0", "supply_v = 6.0").replace("adc_ref_v = 5.0", "adc_ref_v = 6.0")
    path = tmp_path / "six.toml"
    path.write_text(text)
    status = main(["codegen", str(path), "--arduino", str(tmp_path / "libs"), "--maintainer", "A",
                   "--url", "https://example.org", "--board", "none"])  # fmt: skip
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "sensor.analog.adc_ref_v" in err and "above the Uno's 5 V" in err
    assert not (tmp_path / "libs").exists()


@pytest.mark.parametrize(
    ("maintainer", "url", "found"),
    [("", "https://example.org", "--maintainer"), ("A <b>", "https://example.org", "--maintainer"),
     ("A\nname=x", "https://example.org", "--maintainer"), ("A", "ftp://example.org", "--url"),
     ("A", "https://example.org/\nname=x", "--url")],
)  # fmt: skip
def test_the_publisher_fields_are_checked(maintainer, url, found):
    with pytest.raises(ValueError, match=found):
        check_publisher(maintainer, url)


def test_the_library_needs_its_maintainer_and_url(tmp_path, capsys):
    status = main(["codegen", str(MODELS / "adxl250_default.toml"), "--arduino", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "give --maintainer" in err


def test_without_the_toolchain_the_library_is_written_and_no_fit_is_claimed(tmp_path, capsys, monkeypatch):
    path = tmp_path / "uno.toml"
    path.write_text((MODELS / "adxl250_default.toml").read_text().replace("adc_bits = 12", "adc_bits = 10"))
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    argv = ["codegen", str(path), "--arduino", str(tmp_path / "libs"), "--maintainer", "A", "--url", "https://a.org"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "board uno: avr-gcc, avr-size, make not found: no figure for the atmega328p: the sketches not linked, " \
           "no verdict\n" in out  # fmt: skip
    assert "fits" not in out
    assert (tmp_path / "libs" / "accelnav_adxl250_default" / "src" / "AccelNav.h").is_file()
