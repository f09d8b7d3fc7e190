from __future__ import annotations

import pytest

from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.cli import CliClient
from aerobat.firmware.betaflight.errors import ConfigureFailed, LinkClosed, LinkTimeout


class FakeCli:
    """A minimal Betaflight CLI: echoes, answers, prompts."""

    def __init__(self, answers: dict[str, str]) -> None:
        self.answers = answers
        self.out = b""
        self.closed = False
        self.sent: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.sent.append(data)
        text = data.decode()
        if text == "#":
            self.out += b"\r\nEntering CLI Mode, type 'exit' to reboot, or 'help'\r\n\r\n# "
        elif text == "save\n":
            self.out += b"save\r\n# saving\r\n\r\nRebooting"
            self.closed = True
        elif text.endswith("\n"):
            command = text.strip()
            self.out += command.encode() + b"\r\n" + self.answers.get(command, "").encode() + b"\r\n# "

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        if not self.out and self.closed:
            raise LinkClosed("closed")
        data, self.out = self.out[:5], self.out[5:]
        return data

    def close(self) -> None:
        pass


def test_command_strips_echo_and_prompt() -> None:
    cli = CliClient(FakeCli({"get small_angle": "small_angle = 25\r\nAllowed range: 0 - 180"}), quiet_s=0.0)
    assert "Entering CLI Mode" in cli.enter()
    assert cli.command("get small_angle") == "small_angle = 25\nAllowed range: 0 - 180"


def test_error_output_raises() -> None:
    cli = CliClient(FakeCli({"set nope = 1": "###ERROR IN set: INVALID NAME: nope = 1###"}), quiet_s=0.0)
    cli.enter()
    with pytest.raises(ConfigureFailed, match="INVALID NAME"):
        cli.command("set nope = 1")
    assert "INVALID" in cli.command("set nope = 1", check=False)


def test_save_reads_until_closed() -> None:
    cli = CliClient(FakeCli({}), quiet_s=0.0)
    cli.enter()
    assert "Rebooting" in cli.save(timeout_s=1.0)


def test_no_prompt_times_out() -> None:
    class Silent(FakeCli):
        def write(self, data: bytes) -> None:
            pass

    with pytest.raises(LinkTimeout):
        CliClient(Silent({}), timeout_s=0.05).enter()


@pytest.mark.parametrize("line", [
    "set profile_name = " + "\x7f" * 19 + "set p_roll = 123",  # DEL erases the character before it (issue 45 E3)
    "set profile_name = a\rset p_roll = 123", "set profile_name = a\nsave", "set craft_name = a\x00b",
    "set craft_name = a\tb", "set craft_name = \x04", "set craft_name = été", "set craft_name = " + "A" * 300,
    "set profile_name = a#b", "set profile_name = a?b", "", "   ",
])
def test_a_line_the_firmware_would_not_run_as_written_is_never_sent(line: str) -> None:
    """Defence in depth: whatever the caller checked, the client sends only what the CLI runs as written."""
    fake = FakeCli({})
    cli = CliClient(fake, quiet_s=0.0)
    cli.enter()
    sent = len(fake.sent)
    with pytest.raises(ConfigError, match="not sent") as caught:
        cli.command(line)
    assert isinstance(caught.value, ValueError) and str(caught.value).isprintable() and str(caught.value).isascii()
    assert fake.sent[sent:] == []
    assert cli.command("set craft_name = " + "A" * 16 + " ") == ""  # printable, 255 characters at most: sent
