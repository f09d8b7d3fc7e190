from __future__ import annotations

import struct

import pytest

from aerobat.firmware.betaflight.errors import LinkTimeout, MspError
from aerobat.firmware.betaflight.msp import (
    MAX_ANSWER_BYTES,
    MSP_API_VERSION,
    MSP_SET_RAW_RC,
    MSP_STATUS_EX,
    MspClient,
    MspVersion,
    StatusEx,
    crc8_dvb_s2,
    decode_arming_disable_flags,
    encode_request,
)


class FakeTransport:
    """Answers each request with canned bytes, delivered in small chunks."""

    def __init__(self, answers: dict[bytes, bytes], chunk: int = 3) -> None:
        self.answers = answers
        self.chunk = chunk
        self.pending = b""
        self.written: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.written.append(data)
        self.pending += self.answers.get(data, b"")

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        data, self.pending = self.pending[: min(max_bytes, self.chunk)], self.pending[self.chunk :]
        return data

    def close(self) -> None:
        pass


def v2_response(command: int, payload: bytes, error: bool = False) -> bytes:
    body = struct.pack("<BHH", 0, command, len(payload)) + payload
    return (b"$X!" if error else b"$X>") + body + bytes((crc8_dvb_s2(body),))


def v1_response(command: int, payload: bytes) -> bytes:
    checksum = len(payload) ^ command
    for byte in payload:
        checksum ^= byte
    return b"$M>" + bytes((len(payload), command)) + payload + bytes((checksum,))


def test_crc8_dvb_s2_check_value() -> None:
    assert crc8_dvb_s2(b"123456789") == 0xBC  # CRC-8/DVB-S2 catalogue check value


def test_encode_v1_and_v2() -> None:
    assert encode_request(MSP_API_VERSION, version=MspVersion.V1) == b"$M<\x00\x01\x01"
    frame = encode_request(MSP_STATUS_EX)
    assert frame[:3] == b"$X<" and frame[3:8] == struct.pack("<BHH", 0, MSP_STATUS_EX, 0)
    assert frame[8] == crc8_dvb_s2(frame[3:8])
    with pytest.raises(ValueError):
        encode_request(300, version=MspVersion.V1)


@pytest.mark.parametrize("version", [MspVersion.V1, MspVersion.V2])
def test_request_skips_noise_and_chunks(version: MspVersion) -> None:
    request = encode_request(MSP_API_VERSION, version=version)
    response = (v1_response if version is MspVersion.V1 else v2_response)(MSP_API_VERSION, bytes((0, 1, 47)))
    transport = FakeTransport({request: b"\r\n# junk$$M" + response})
    client = MspClient(transport, version=version)
    api = client.api_version()
    assert (api.protocol, api.major, api.minor) == (0, 1, 47)


@pytest.mark.parametrize("lost", [1, 2, 3, 5, 7, 8])
def test_answers_after_a_torn_frame_are_read_at_once(lost: int) -> None:
    """Bytes lost from an answer's header (the SITL's UART thread races its main loop; a real UART overruns)
    must not hold the later answers back: a header whose size comes from the next frame's bytes declares
    kilobytes, and waiting for them silenced the link for longer than its timeout."""
    ack = v2_response(MSP_SET_RAW_RC, b"")
    torn = ack[: len(ack) - 1 - lost] if lost < len(ack) - 1 else ack[:2]
    transport = FakeTransport({}, chunk=4096)
    transport.pending = torn + ack + ack
    client = MspClient(transport)
    answers = client.collect(0.0)
    assert [command for command, _ in answers] == [MSP_SET_RAW_RC, MSP_SET_RAW_RC]


def test_a_header_too_large_for_any_answer_is_skipped_and_a_partial_answer_is_waited_for() -> None:
    body = struct.pack("<BHH", 0, MSP_STATUS_EX, MAX_ANSWER_BYTES + 1)
    transport = FakeTransport({}, chunk=4096)
    ack = v2_response(MSP_SET_RAW_RC, b"")
    transport.pending = b"$X>" + body + ack[:5]  # the torn header, then an answer still arriving
    client = MspClient(transport)
    assert client.collect(0.0) == []
    transport.pending = ack[5:]
    assert client.collect(0.0) == [(MSP_SET_RAW_RC, b"")]


def test_error_frame_raises() -> None:
    transport = FakeTransport({encode_request(MSP_STATUS_EX): v2_response(MSP_STATUS_EX, b"", error=True)})
    with pytest.raises(MspError):
        MspClient(transport).status_ex()


def test_timeout() -> None:
    with pytest.raises(LinkTimeout):
        MspClient(FakeTransport({}), timeout_s=0.05).api_version()


def test_status_ex_decoding() -> None:
    mask = (1 << 2) | (1 << 12)  # RXLOSS, CALIB
    payload = struct.pack("<HHHIBH", 125, 0, 0x21, 0b1, 0, 0) + bytes((4, 0)) + bytes((0,)) + bytes((29,))
    payload += struct.pack("<I", mask) + bytes((0,)) + struct.pack("<H", 0)
    status = StatusEx.decode(payload)
    assert status.pid_cycle_time_us == 125 and status.armed
    assert status.arming_disable_flags == ("RXLOSS", "CALIB")


def test_arming_flag_names() -> None:
    assert decode_arming_disable_flags(1 << 9 | 1 << 13) == ("BOOTGRACE", "CLI")
    assert decode_arming_disable_flags(1 << 31) == ("BIT31",)
