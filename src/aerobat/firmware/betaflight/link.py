"""The firmware link: everything that talks to Betaflight, independent of simulated physics.

A :class:`FirmwareLink` owns one byte :class:`~.transport.Transport` to the
flight controller's MSP/CLI port and offers an MSP client and a CLI client on
it. The same code talks to the SITL (TCP to its UART1) or, with a serial
transport, to a real flight controller (see :mod:`.transport` for what a
serial transport needs).

RC is not part of this link: the SITL takes RC frames as UDP packets
(:mod:`.sitl`), a real flight controller from its receiver; both use the
encoding of :mod:`.rc`, re-exported here.
"""

from __future__ import annotations

from .cli import CLI_PROMPT, CliClient
from .msp import (
    ARMING_DISABLE_FLAG_NAMES,
    ApiVersion,
    Attitude,
    MspClient,
    MspVersion,
    StatusEx,
    decode_arming_disable_flags,
)
from .rc import (
    RADIO_LOST_US,
    RC_CHANNEL_COUNT,
    RcCommand,
    stick_to_us,
    throttle_to_us,
    us_to_stick,
    us_to_throttle,
)
from .transport import TcpTransport, Transport

__all__ = [
    "ARMING_DISABLE_FLAG_NAMES",
    "CLI_PROMPT",
    "RADIO_LOST_US",
    "RC_CHANNEL_COUNT",
    "ApiVersion",
    "Attitude",
    "CliClient",
    "FirmwareLink",
    "MspClient",
    "MspVersion",
    "RcCommand",
    "StatusEx",
    "TcpTransport",
    "Transport",
    "decode_arming_disable_flags",
    "stick_to_us",
    "throttle_to_us",
    "us_to_stick",
    "us_to_throttle",
]


class FirmwareLink:
    """MSP and CLI access to one flight controller port.

    MSP and the CLI share the port: once the CLI is entered, the firmware
    answers CLI text only until it reboots.

    Parameters
    ----------
    transport : Transport
        Byte link to the flight controller; the link closes it.
    msp_timeout_s : float
        Default MSP answer timeout.
    cli_timeout_s : float
        Default CLI prompt timeout.
    """

    def __init__(self, transport: Transport, msp_timeout_s: float = 1.0, cli_timeout_s: float = 5.0) -> None:
        self.transport = transport
        self.msp = MspClient(transport, timeout_s=msp_timeout_s)
        self.cli = CliClient(transport, timeout_s=cli_timeout_s)

    @classmethod
    def connect_tcp(cls, port: int, host: str = "127.0.0.1", connect_timeout_s: float = 5.0) -> FirmwareLink:
        """Connect to a TCP-served UART (the SITL's UART1 is ``tcp_base_port + 1``)."""
        return cls(TcpTransport(host, port, connect_timeout_s))

    def close(self) -> None:
        """Close the transport."""
        self.transport.close()

    def __enter__(self) -> FirmwareLink:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
