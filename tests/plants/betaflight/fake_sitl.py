#!/usr/bin/env python3
"""A stand-in for the lockstep SITL binary, speaking its UDP protocol (for fast tests).

Answers every state packet with one motor packet: (number of RC packets
received so far, last RC throttle channel / 1000, state timestamp, 0, then
zeros for the set point and PID terms: the 76-byte lockstep packet).
FAKE_SITL_MODE=exit makes it exit before getting ready; =mute makes it
never answer. With BF_SITL_SHM_FD the packets go through the shared-memory
exchange instead (the C helper's firmware-side functions, from
FAKE_SITL_SHM_LIB); its RC count is the RC packets published.
"""

import ctypes
import mmap
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
if os.environ.get("BF_SITL_SHM_FD"):
    region = mmap.mmap(int(os.environ["BF_SITL_SHM_FD"]), 4096)
    lib = ctypes.CDLL(os.environ["FAKE_SITL_SHM_LIB"])
    for name in ("aerobat_shm_wait_state", "aerobat_shm_take_rc"):
        getattr(lib, name).restype = ctypes.c_int64
    i64 = ctypes.c_int64
    address = ctypes.addressof(ctypes.c_char.from_buffer(region))
    state_buffer, rc_buffer = ctypes.create_string_buffer(144), ctypes.create_string_buffer(40)
    seen, rc_seen, parent = 0, 0, os.getppid()
    while True:
        got = lib.aerobat_shm_wait_state(ctypes.c_void_p(address), state_buffer, i64(144), i64(seen), i64(20_000),
                                         i64(500_000_000))
        if got < 0:
            if os.getppid() != parent:
                sys.exit(1)
            continue
        seen = got
        now = lib.aerobat_shm_take_rc(ctypes.c_void_p(address), rc_buffer, i64(40), i64(rc_seen))
        if now != rc_seen:
            rc_count += now - rc_seen
            rc_seen = now
            throttle = struct.unpack("<d16H", rc_buffer.raw)[3] / 1000.0
        if mode != "mute":
            answer = struct.pack("<4f3f12f", rc_count, throttle, struct.unpack_from("<d", state_buffer.raw)[0], 0.0,
                                 *([0.0] * 15))
            lib.aerobat_shm_publish_motor(ctypes.c_void_p(address), answer, i64(len(answer)), i64(seen))
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
