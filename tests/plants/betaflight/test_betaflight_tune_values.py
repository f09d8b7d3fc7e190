"""Every value of a tune is checked by the firmware's own grammar before it can reach its CLI (issue 45 E3, E7).

No firmware here: reading and translating a tune happen before any SITL starts. Each defect of the
issue has a test that failed on the code before the fix: a blackbox header's DEL characters erased
``set profile_name = `` on the firmware's line and ran ``set p_roll = 123`` (E3); ``set d_roll = abc``
ended in a ValueError, ``set p_roll = 1e2`` was applied and failed at read-back, a byte-order mark
was refused and an INAV diff was called an unknown setting (E7).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import tomli_w

from aerobat.cli import main
from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.settings import load_settings
from aerobat.firmware.betaflight.sitl_table import load_table
from aerobat.firmware.betaflight.translate import translate
from aerobat.firmware.betaflight.tune import TuneError, load_tune, parse_cli, tune_from_blackbox_header
from aerobat.plants.fpv.params import load_betaflight

HEADER = (b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n"
          b"H Firmware revision:Betaflight 4.2.9 (e097f4ab7) STM32F7X2\n"
          b"H rollPID:47,85,38\nH rates_type:0\n")
DELS = b"\x7f" * 19 + b"set p_roll = 123"  # 19 DELs erase "set profile_name = " on the firmware's line
CRAFTED = {"del": DELS, "cr": b"ab\rset p_roll = 123", "nul": b"ab\x00cd", "esc": b"\x1b[2Jab",
           "non-ascii": "été".encode(), "huge": b"A" * (1 << 20)}
V431 = "# Betaflight / STM32F7X2 (S7X2) 4.3.1 Jul 13 2022 / 03:32:52 (8d4f005) MSP API: 1.44\n"
V460 = "# Betaflight / STM32F7X2 (S7X2) 4.6.0 Jul 13 2025 / 03:32:52 (8d4f005) MSP API: 1.47\n"


def _log(tmp_path: Path, *fields: bytes) -> Path:
    path = tmp_path / "crafted.bbl"
    path.write_bytes(HEADER + b"".join(fields) + b"I\x00\x01\x02")  # the frames follow the header
    return path


@pytest.mark.parametrize("kind", CRAFTED)
def test_a_header_field_that_is_no_cli_text_is_bad_input_naming_the_field(tmp_path: Path, kind: str) -> None:
    """E3: DEL, CR, NUL, ESC, non-ASCII or a megabyte in a header value never get into a tune."""
    path = _log(tmp_path, b"H profile_name:" + CRAFTED[kind] + b"\n")
    with pytest.raises(TuneError, match=r"crafted\.bbl#log1: header field profile_name:.*(character|characters, more)"
                                        r".*allowed 1-8 printable ASCII") as caught:
        translate(load_tune(path))
    message = str(caught.value)
    assert message.isascii() and message.isprintable() and len(message) < 400  # one readable line


def test_a_crafted_header_is_refused_by_learn_before_anything_flies(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """E3 through the command line the issue used: one line, exit 2, nothing stored."""
    path = _log(tmp_path, b"H profile_name:" + DELS + b"\n")
    db = tmp_path / "s.sqlite"
    code = main(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "420", "--vehicle", "fpv5",
                 "--plant", "betaflight", "--tune", str(path), "--iterations", "1", "--db", str(db)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith(f"aerobat: error: {path}#log1: header field profile_name:")
    assert "0x7f (DEL)" in err and "allowed 1-8" in err
    assert not db.exists()


def test_header_numbers_are_ascii_decimal_integers() -> None:
    header = {"Firmware revision": "Betaflight 4.2.9 (e097f4ab7) STM32F7X2", "rollPID": "47,85,38"}
    for field, value in (("rollPID", "٤٧,85,38"), ("rollPID", "47,8e1,38"), ("rates_type", "٣")):
        with pytest.raises(TuneError, match=rf"mem: header field {field}:"):
            translate(tune_from_blackbox_header({**header, field: value}, source="mem"))
    with pytest.raises(TuneError, match=r"mem: header field p_roll: p_roll = '4_5': not an integer .*allowed 0\.\.250"):
        translate(tune_from_blackbox_header({**header, "p_roll": "4_5"}, source="mem"))


@pytest.mark.parametrize(("version", "value"), [(V431, "abc"), (V431, "1e9"), (V431, "40.5"), ("", "40.5"),
                                                ("", "abc")])
def test_a_d_term_that_is_no_integer_is_bad_input_naming_line_and_range(version: str, value: str) -> None:
    """E7: before 4.6 (or with no version line) D terms are paired; a value that is no integer was a ValueError."""
    line = 2 if version else 1
    with pytest.raises(TuneError, match=rf"f\.txt: line {line}: d_roll = '{re.escape(value)}': not an integer as "
                                        r"the firmware reads one .*allowed 0\.\.250"):
        translate(parse_cli(f"{version}set d_roll = {value}\nset d_min_roll = 30\n", source="f.txt"))


@pytest.mark.parametrize("value", ["1e2", "4_5", "45.9", "0x2d", "45 6", "٤٥", "--45"])
def test_an_integer_in_another_grammar_is_bad_input_not_flown(value: str) -> None:
    """E7: the firmware reads ``1e2`` as 1, ``4_5`` as 4, ``45.9`` as 45 (atoi); Python read 100, 45, 45.9."""
    with pytest.raises(TuneError, match=r"f\.txt: line 2: p_roll = .*allowed 0\.\.250"):
        translate(parse_cli(f"{V460}set p_roll = {value}\n", source="f.txt"))


def test_values_are_applied_as_the_firmware_prints_them_back() -> None:
    report = translate(parse_cli(f"{V460}set p_roll = +045\nset rates_type = actual\nset i_roll = -0\n"
                                 "set roll_rc_rate = 0\n", source="f"))
    assert report.values() == {"p_roll": "45", "rates_type": "ACTUAL", "i_roll": "0"}  # what `get` reads back
    assert "roll_rc_rate" in [name for name, *_ in report.refused]  # well formed, out of 4.6's range: refused


def test_a_byte_order_mark_is_skipped(tmp_path: Path) -> None:
    """E7: a diff saved by an editor that writes a UTF-8 BOM was refused at line 1."""
    path = tmp_path / "bom.txt"
    path.write_bytes(b"\xef\xbb\xbf" + V431.replace("\n", "\r\n").encode() + b"set p_roll = 50\r\n")
    tune = load_tune(path)
    assert tune.version == (4, 3, 1) and translate(tune).values() == {"p_roll": "50"}
    log = tmp_path / "bom.bbl"
    log.write_bytes(b"\xef\xbb\xbf" + HEADER)
    assert translate(load_tune(log)).values()["p_roll"] == "47"


@pytest.mark.parametrize(("version", "writer"), [
    ("# INAV/MATEKF722SE 7.1.2 Jun  4 2024 / 08:46:38 (f5c4ed6d)", "INAV 7.1.2"),
    ("# EmuFlight / HELIOSPRING (HESP) 0.4.1 Nov 11 2021 / 17:28:01 (f6a0ab6be) MSP API: 1.51", "EmuFlight 0.4.1"),
])
def test_another_firmwares_diff_is_refused_as_such(version: str, writer: str) -> None:
    """E7: INAV and EmuFlight diffs were refused as 'unknown setting' at their first setting."""
    text = f"# diff all\n\n# version\n{version}\n\n# master\nset gyro_main_lpf_hz = 110\n"
    with pytest.raises(TuneError, match=rf"f\.txt: line 4: not a Betaflight diff or dump: written by {writer} "):
        parse_cli(text, source="f.txt")


def test_a_plant_files_tune_is_held_to_the_same_rules(tmp_path: Path) -> None:
    """A ``[tune]`` written into a Betaflight plant file (or a stored session) is checked as a parsed one is."""
    tune = {"firmware": "Betaflight / X 4.6.0", "version": [4, 6, 0], "source": "crafted", "kind": "cli",
            "active_profile": 0, "active_rateprofile": 0,
            "lines": [["profile", 0, "profile_name", DELS.decode(), 1]]}
    path = tmp_path / "bf.toml"
    path.write_text(tomli_w.dumps({"tune": tune}))
    with pytest.raises(ConfigError, match=r"tune crafted: line 1: profile_name = .*0x7f \(DEL\)"):
        load_betaflight(path)
    tune["lines"] = [["master", 0, "p_roll", "1e2", 1]]
    path.write_text(tomli_w.dumps({"tune": tune}))
    with pytest.raises(TuneError, match=r"crafted: line 1: p_roll = '1e2'"):
        translate(load_betaflight(path).tune)


def test_features_are_sent_as_the_firmware_reads_them() -> None:
    report = translate(parse_cli(f"{V460}feature -ANTI_GRAVITY\nfeature --ANTI_GRAVITY\n", source="f"))
    assert report.commands == ("feature -ANTI_GRAVITY",)
    assert [name for name, *_ in report.refused] == ["feature ANTI_GRAVITY"]


def test_the_last_check_before_the_cli_refuses_what_the_firmware_would_change() -> None:
    """Whatever made the settings, configuring refuses a value the build does not take as written."""
    from aerobat.firmware.betaflight.configure import check_commands

    settings = load_settings()
    check_commands(settings)  # the shipped settings pass
    for extra, message in (({"p_roll": "1e2"}, "not an integer"), ({"p_roll": "045"}, "read it back as '45'"),
                           ({"profile_name": "a\x7fb"}, r"0x7f \(DEL\)"), ({"p_roll": "251"}, r"allowed 0\.\.250"),
                           ({"no_such_setting": "1"}, "not a setting of this SITL build")):
        with pytest.raises(ConfigError, match=message):
            check_commands(settings.with_values(extra, "test"))


def test_the_table_knows_each_settings_type_and_range() -> None:
    table = load_table()
    assert (table.get("profile_name").min_length, table.get("profile_name").max_length) == (1, 8)
    assert table.get("craft_name").max_length == 16
    assert table.get("p_roll").checked(" 45 ").value == "45"
    assert table.get("p_roll").checked("١٢").verdict == "malformed"
    assert table.get("profile_name").checked("a#b").verdict == "rejected"  # the CLI takes the rest for a comment


def test_the_tune_command_reads_a_tune_without_flying(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    path = tmp_path / "t.txt"
    path.write_text(f"{V460}set p_roll = 50\nset rates_type = KISS\nset roll_rc_rate = 70\n")
    assert main(["tune", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {"name": "p_roll", "value": "50", "line": 2, "where": "line 2"} in data["applied"]
    assert "set p_roll = 50" in data["commands"] and data["rates_type"] == "KISS"
    bad = _log(tmp_path, b"H profile_name:" + DELS + b"\n")
    assert main(["tune", str(bad)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "header field profile_name" in err


def test_lines_end_where_the_firmwares_cli_ends_them(tmp_path: Path) -> None:
    """Found by the tunes fuzz phase: Python's splitlines() and strip() also cut at a form feed, U+2028, a TAB."""
    for text, where in ((f"{V460}set p_roll = 45\x0c\n", r"line 2: p_roll = '45\\x0c': the control character 0x0c"),
                        (f"{V460}set p_roll = 4\u20285\n", r"line 2: p_roll = '4\\u20285': the non-ASCII character"),
                        (f"{V460}set p_roll = 45\t\n", r"line 2: p_roll = '45\\t': the control character 0x09")):
        with pytest.raises(TuneError, match=where):
            parse_cli(text, source="f.txt")
    with pytest.raises(TuneError, match=r"header field thr_mid:.50\\t.: the control character 0x09 \(TAB\)"):
        load_tune(_log(tmp_path, b"H thr_mid:50\t\n"))
    crlf = tmp_path / "crlf.bbl"
    crlf.write_bytes(HEADER.replace(b"\n", b"\r\n") + b"I\x00")  # a CR before the LF ends the line
    assert translate(load_tune(crlf)).values()["p_roll"] == "47"
    latin = tmp_path / "latin.txt"
    latin.write_bytes(f"{V460}set p_roll = 45\n".encode() + b"set profile_name = caf\xe9\n")
    with pytest.raises(TuneError, match=r"latin\.txt: line 3: byte 0xe9 is not UTF-8 text"):
        load_tune(latin)


def test_a_file_larger_than_any_tune_is_refused_at_once(tmp_path: Path) -> None:
    """Found by the tunes fuzz phase: a 16 MB diff took 9 s and 500 MB; a header of 500,000 lines 4 s."""
    from aerobat.firmware.betaflight.tune import MAX_CLI_BYTES, MAX_HEADER_LINES

    big = tmp_path / "big.txt"
    big.write_bytes(V460.encode() + b"set p_roll = 45\n" * (MAX_CLI_BYTES // 16 + 1))
    with pytest.raises(TuneError, match=r"big\.txt: \d+ bytes, larger than any Betaflight CLI diff or dump"):
        load_tune(big)
    long = tmp_path / "long.bbl"
    long.write_bytes(HEADER + b"".join(b"H Field %d:1\n" % k for k in range(MAX_HEADER_LINES)) + b"I")
    with pytest.raises(TuneError, match=rf"long\.bbl: the header at byte 0 has more than {MAX_HEADER_LINES} lines"):
        load_tune(long)
    many = tmp_path / "many.bbl"
    many.write_bytes(HEADER + b"I\x00" + HEADER.replace(b"47,85,38", b"50,85,38") + b"I\x00"
                     + b"H Product:x\nH Firmware revision:Betaflight 4.2.9\nI\n" * 100_000)
    assert translate(load_tune(many, log_index=2)).values()["p_roll"] == "50"
    with pytest.raises(TuneError, match=r"many\.bbl:100003: no such log; the file holds 100002 log\(s\)"):
        load_tune(many, log_index=100_003)
