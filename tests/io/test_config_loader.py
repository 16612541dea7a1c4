"""The strict YAML loader: YAML 1.2 numbers and booleans, duplicate keys, line numbers in errors."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import Field

from nlsid.errors import InputError
from nlsid.io.config import StrictModel, load_config, load_yaml


class Inner(StrictModel):
    gain: float = Field(gt=0)
    enabled: bool = False


class Outer(StrictModel):
    rate: float
    items: list[Inner]


def write(tmp_path, text: str):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, value", [("1e3", 1000.0), ("1.0e3", 1000.0), ("-2.5E-2", -0.025), ("12", 12),
                                          (".inf", float("inf")), ("0x10", 16)])
def test_numbers_follow_yaml_1_2(tmp_path, text, value):
    data, _ = load_yaml(write(tmp_path, f"x: {text}\n"))
    assert data["x"] == value and type(data["x"]) is type(value)


@pytest.mark.parametrize("text", ["on", "off", "yes", "no", "y", "n"])
def test_only_true_and_false_are_booleans(tmp_path, text):
    data, _ = load_yaml(write(tmp_path, f"x: {text}\n"))
    assert data["x"] == text


def test_true_false_are_booleans(tmp_path):
    data, _ = load_yaml(write(tmp_path, "a: true\nb: False\n"))
    assert data == {"a": True, "b": False}


def test_duplicate_key_is_an_error_with_its_line(tmp_path):
    with pytest.raises(InputError, match=r"c.yaml:3: a.b: duplicate key"):
        load_yaml(write(tmp_path, "a:\n  b: 1\n  b: 2\n"))


def test_validation_error_names_line_and_key_path(tmp_path):
    text = "rate: 1e3\nitems:\n  - gain: 1.0\n  - gain: 2.0\n    enabled: yes\n"
    with pytest.raises(InputError) as err:
        load_config(write(tmp_path, text), Outer)
    assert str(err.value) == f"{tmp_path / 'c.yaml'}:5: items[1].enabled: expected true or false, got 'yes'"


def test_bound_violation_message(tmp_path):
    with pytest.raises(InputError, match=r":3: items\[0\].gain: must be > 0"):
        load_config(write(tmp_path, "rate: 1.0\nitems:\n  - gain: -1.0\n"), Outer)


def test_unknown_key_is_an_error(tmp_path):
    with pytest.raises(InputError, match=r":2: colour: unknown key"):
        load_config(write(tmp_path, "rate: 1.0\ncolour: red\nitems: []\n"), Outer)


def test_valid_config_loads(tmp_path):
    config = load_config(write(tmp_path, "rate: 2e3\nitems:\n  - {gain: 3}\n"), Outer)
    assert config.rate == 2000.0 and config.items[0].gain == 3.0 and not config.items[0].enabled


TEXT = "rate: 2e3  # Hz\nitems:\n  - {gain: 3, enabled: true}\nname: Läufer\n"


@pytest.mark.parametrize("encoding", ["utf-8", "utf-8-sig", "utf-16", "utf-16-le", "utf-16-be", "utf-32", "utf-32-le",
                                      "utf-32-be"])
def test_unicode_encodings_with_and_without_byte_order_mark(tmp_path, encoding):
    path = tmp_path / "c.yaml"
    path.write_bytes(TEXT.encode(encoding))  # "utf-16"/"utf-32" write a BOM, the -le/-be forms none
    data, lines = load_yaml(path)
    assert data == {"rate": 2000.0, "items": [{"gain": 3, "enabled": True}], "name": "Läufer"}
    assert lines[("name",)] == 4


@pytest.mark.parametrize("data, message", [
    (b"rate: 1\nname: \xff\xfe\n", r"c.yaml:2: not a text file in UTF-8 \(byte 14: invalid start byte\)"),
    ("rate: 1\nname: Läufer\n".encode("latin-1"), r"c.yaml:2: not a text file in UTF-8 \(byte 15: invalid continuation"),
    ("rate: 1\n".encode("utf-16-le")[:-1], r"c.yaml:1: not a text file in UTF-16 little-endian \(byte 14: truncated data\)"),
    (b"rate: 1\nname: a\x00b\n", r"c.yaml:2: invalid YAML: control character U\+0000 is not allowed"),
    (b"a: &x [1, *x]\n", r"c.yaml:1: a\[1\]: an alias refers to a collection that contains it"),
    (b"rate: 1\nitems: []\n\"\\x1e\": 2\n", r"c.yaml:3: \['\\x1e'\]: unknown key"),
])
def test_undecodable_and_unloadable_bytes(tmp_path, data, message):
    path = tmp_path / "c.yaml"
    path.write_bytes(data)
    with pytest.raises(InputError, match=message) as err:
        load_config(path, Outer)
    assert len(str(err.value).splitlines()) == 1


def test_utf16_design_config_designs_what_its_utf8_text_does(run_cli, tmp_path):
    text = (Path(__file__).resolve().parents[2] / "configs" / "stage_design.yaml").read_text(encoding="utf-8")
    summaries = {}
    for encoding in ("utf-8", "utf-16"):
        path = tmp_path / f"{encoding}.yaml"
        path.write_bytes(text.encode(encoding))
        result = run_cli("design", path, "-o", tmp_path / f"{encoding}.h5", "--json")
        assert result.exit_code == 0, result.stderr
        summaries[encoding] = {key: value for key, value in result.json().items() if key != "output"}
    assert summaries["utf-16"] == summaries["utf-8"] and summaries["utf-8"]["runs"] == 36
