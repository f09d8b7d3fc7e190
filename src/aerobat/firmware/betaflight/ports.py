"""The ports of one SITL instance: chosen free on 127.0.0.1, passed to the firmware in its environment."""

from __future__ import annotations

import socket
from dataclasses import dataclass

from .errors import FirmwareNotResponding

__all__ = ["SitlPorts", "allocate_ports"]


@dataclass(frozen=True)
class SitlPorts:
    """The ports of one SITL instance, all on 127.0.0.1.

    Attributes
    ----------
    udp_base : int
        Motors go to ``udp_base + 2`` (bound by us), state to ``udp_base + 3``
        and RC to ``udp_base + 4`` (bound by the firmware). Stock: 9000.
    tcp_base : int
        UART n is served on ``tcp_base + n`` (UART1: MSP and CLI). Stock: 5760.
    """

    udp_base: int
    tcp_base: int

    @property
    def motor_port(self) -> int:
        """UDP port the firmware sends motor packets to."""
        return self.udp_base + 2

    @property
    def state_port(self) -> int:
        """UDP port the firmware receives state packets on."""
        return self.udp_base + 3

    @property
    def rc_port(self) -> int:
        """UDP port the firmware receives RC packets on."""
        return self.udp_base + 4

    @property
    def uart1_port(self) -> int:
        """TCP port of UART1 (MSP, CLI)."""
        return self.tcp_base + 1


def _port_is_free(kind: int, port: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def allocate_ports(max_tries: int = 50) -> tuple[SitlPorts, socket.socket]:
    """Pick free ports for one instance and bind its motor socket.

    The kernel chooses the motor port; the state, RC and UART1 ports next to
    it are checked free. There is a short race until the firmware binds them;
    the firmware exits when a bind fails and :class:`SitlProcess` retries.

    Returns
    -------
    ports : SitlPorts
    motor_socket : socket.socket
        UDP socket bound to ``ports.motor_port``.
    """
    for _ in range(max_tries):
        motor_socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        motor_socket.bind(("127.0.0.1", 0))
        udp_base = motor_socket.getsockname()[1] - 2
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.bind(("127.0.0.1", 0))
            tcp_base = probe.getsockname()[1] - 1
        ports = SitlPorts(udp_base, tcp_base)
        if (
            ports.rc_port <= 65535
            and _port_is_free(socket.SOCK_DGRAM, ports.state_port)
            and _port_is_free(socket.SOCK_DGRAM, ports.rc_port)
            and _port_is_free(socket.SOCK_STREAM, ports.uart1_port)
        ):
            return ports, motor_socket
        motor_socket.close()
    raise FirmwareNotResponding(f"no free ports for a SITL instance after {max_tries} tries")
