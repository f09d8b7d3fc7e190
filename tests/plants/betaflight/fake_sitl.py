#!/usr/bin/env python3
"""A stand-in for the lockstep SITL binary, speaking its UDP protocol (for fast tests).

Answers every state packet with one motor packet: (number of RC packets
received so far, last RC throttle channel / 1000, state timestamp, 0, then
zeros for the set point and PID terms: the 76-byte lockstep packet).
FAKE_SITL_MODE=exit makes it exit before getting ready; =mute makes it
never answer.
"""

import os
import socket
import struct
import sys

udp_base = int(os.environ.get("BF_SITL_UDP_BASE_PORT", "9000"))
mode = os.environ.get("FAKE_SITL_MODE", "")
if mode == "exit":
    print("[SITL] fake: exiting early", flush=True)
    sys.exit(3)
state = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
state.bind(("127.0.0.1", udp_base + 3))
rc = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
rc.bind(("127.0.0.1", udp_base + 4))
rc.setblocking(False)
motors = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
print("[SITL] lockstep: ready, simulated clock at 0 us", flush=True)
rc_count, throttle = 0, 0.0
while True:
    packet = state.recv(1024)
    while True:
        try:
            rc_packet = rc.recv(1024)
        except BlockingIOError:
            break
        rc_count += 1
        throttle = struct.unpack("<d16H", rc_packet)[3] / 1000.0
    if mode != "mute":
        motors.sendto(
            struct.pack("<4f3f12f", rc_count, throttle, struct.unpack_from("<d", packet)[0], 0.0, *([0.0] * 15)),
            ("127.0.0.1", udp_base + 2),
        )
