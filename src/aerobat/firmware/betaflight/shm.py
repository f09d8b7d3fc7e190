"""The lockstep firmware's shared-memory exchange, the driver's side (issue 27).

With ``BF_SITL_SHM_FD`` the patched firmware (``lockstep.patch``) takes its state and RC packets
from, and puts its motor packets into, a 4096-byte shared memory region instead of UDP: a
sequence word per direction, a short spin, then a futex sleep with a timeout. :class:`ShmRegion`
creates that region as a memfd (no file in ``/dev/shm``: the memory goes when the last process
that maps it is gone, whichever way it ends), maps it here and hands the descriptor to the
firmware process. The atomics and the futex calls are in ``shm_exchange.c``, compiled once with
the host C compiler into ``<cache>/shm-<source sha256[:12]>/`` (:func:`ensure_library`) and
called through ctypes here and from the compiled loop (:mod:`aerobat.plants.betaflight.lockstep`).
"""

from __future__ import annotations

import ctypes
import fcntl
import hashlib
import math
import mmap
import os
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .build import default_cache_dir
from .errors import FirmwareUnavailable

__all__ = ["SHM_SIZE", "ShmRegion", "SpinChoices", "ensure_library", "library"]

SHM_SIZE = 4096
"""Bytes of the region (sitl.c's and shm_exchange.c's SHM_SIZE)."""
LIBRARY_NAME = "libaerobat_shm.so"
_SOURCE = Path(__file__).with_name("shm_exchange.c")
SPIN_S = 20e-6
"""The default longest spin of the driver for the firmware's answer before it sleeps on the futex [s]
(adaptive below it): :attr:`aerobat.plants.fpv.params.Firmware.spin_us`."""

_OFF_DRIVER_SPIN_NS = 80  # shm_exchange.c's SHM_OFF_DRIVER_SPIN_NS
_OFF_FIRMWARE_SPIN_NS = 136  # SHM_OFF_SPIN_NS
_OFF_DRIVER_POLICY = 1024  # SHM_OFF_DRIVER_POLICY
_POLICY_STRUCT = struct.Struct("<3q6I2d4Q")
"""shm_exchange.c's struct spin_policy: epoch start, last wait, epoch length [ns]; the epoch's and the last
wait's state packet, home mode, mode, epochs until the probe, backoff; cost per step spinning, sleeping [ns];
steps spinning, sleeping; switches; probes."""
_LEARNED: tuple[int, int, int, float, float] | None = None
"""What the last region of this process learned (home mode, epochs until its next probe, backoff, costs):
the next one starts there, so
a study's trials do not each probe from scratch (the probes still follow a load that changes)."""


@dataclass(frozen=True)
class SpinChoices:
    """What the driver's measured spin policy chose over a flight (zeros when it was not asked to measure)."""

    steps_spinning: int
    """Lockstep steps flown with the driver spinning for the answer (counted at the waits)."""
    steps_sleeping: int
    switches: int
    """Times the mode it flies between probes changed."""
    probes: int
    """Short epochs it tried the other mode for."""
    step_ns_spinning: float
    """Wall time per step last measured spinning [ns] (0: never)."""
    step_ns_sleeping: float
    sleeping_now: bool = False
    """The mode it flies between probes is sleeping."""

    @property
    def sleeping_share(self) -> float:
        """The steps flown sleeping at once ÷ all (NaN: none counted)."""
        total = self.steps_spinning + self.steps_sleeping
        return self.steps_sleeping / total if total else math.nan

_loaded: ctypes.CDLL | None = None


def ensure_library(cache_dir: Path | None = None) -> Path:
    """The compiled ``shm_exchange.c`` (built with ``$CC``/gcc/cc on first use, cached by the source's hash)."""
    source = _SOURCE.read_bytes()
    target_dir = (cache_dir or default_cache_dir()) / f"shm-{hashlib.sha256(source).hexdigest()[:12]}"
    library_path = target_dir / LIBRARY_NAME
    if library_path.is_file():
        return library_path
    compiler = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")
    if compiler is None:
        raise FirmwareUnavailable("no C compiler found (gcc or cc) to build the shared-memory exchange "
                                  "(Debian: apt-get install build-essential)")
    target_dir.mkdir(parents=True, exist_ok=True)
    with open(target_dir.with_name(target_dir.name + ".lock"), "a") as lock:  # internal
        fcntl.flock(lock, fcntl.LOCK_EX)  # one compile at a time; released when the file closes
        if library_path.is_file():
            return library_path
        with tempfile.TemporaryDirectory(dir=target_dir) as scratch:
            staged = Path(scratch) / LIBRARY_NAME
            result = subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-Wall", "-o", str(staged), str(_SOURCE)],
                                    capture_output=True, text=True, check=False)
            if result.returncode != 0:
                raise FirmwareUnavailable(f"compiling {_SOURCE.name} failed (exit status {result.returncode}): "
                                          f"{result.stderr.strip()[-2000:]}")
            staged.replace(library_path)
    return library_path


def library() -> ctypes.CDLL:
    """The exchange library, loaded into this process (also for the compiled loop's symbols)."""
    global _loaded
    if _loaded is None:
        import llvmlite.binding

        path = ensure_library()
        llvmlite.binding.load_library_permanently(str(path))
        lib = ctypes.CDLL(str(path))
        i64, ptr = ctypes.c_int64, ctypes.c_void_p
        for name, args in (("aerobat_shm_publish_state", (ptr, ptr, i64)), ("aerobat_shm_publish_rc", (ptr, ptr, i64)),
                           ("aerobat_shm_wait_motor", (ptr, ptr, i64, i64, i64)),
                           ("aerobat_shm_poll_motor", (ptr, ptr, i64)),
                           ("aerobat_shm_wait_state", (ptr, ptr, i64, i64, i64, i64)),
                           ("aerobat_shm_take_rc", (ptr, ptr, i64, i64)),
                           ("aerobat_shm_choose_spin", (ptr, i64, i64, i64))):
            function = getattr(lib, name)
            function.argtypes, function.restype = args, i64
        lib.aerobat_shm_init.argtypes, lib.aerobat_shm_init.restype = (ptr,), None
        lib.aerobat_shm_publish_motor.argtypes, lib.aerobat_shm_publish_motor.restype = (ptr, ptr, i64, i64), None
        _loaded = lib
    return _loaded


def _address(buffer: mmap.mmap) -> int:
    holder = (ctypes.c_char * len(buffer)).from_buffer(buffer)
    try:
        return ctypes.addressof(holder)
    finally:
        del holder  # no export stays: the buffer can be closed


class ShmRegion:
    """One exchange region: a memfd of :data:`SHM_SIZE` bytes mapped here, its descriptor for the firmware.

    Pass :attr:`fd` to the firmware process (``pass_fds``, ``BF_SITL_SHM_FD``), then call
    :meth:`handed_over` to close this process's descriptor (the mapping stays). :meth:`close`
    unmaps it; the memory is freed when the firmware's mapping is gone too.
    """

    def __init__(self, spin_s: float = SPIN_S) -> None:
        self.spin_s = spin_s
        """The longest the driver spins for an answer before it sleeps [s] (:meth:`wait_motor`)."""
        self._lib = library()
        self.fd: int | None = os.memfd_create("aerobat-betaflight-lockstep", os.MFD_CLOEXEC)
        try:
            os.ftruncate(self.fd, SHM_SIZE)
            self._map: mmap.mmap | None = mmap.mmap(self.fd, SHM_SIZE)
        except BaseException:
            os.close(self.fd)
            raise
        self.address = _address(self._map)
        self._lib.aerobat_shm_init(self.address)
        if _LEARNED is not None:  # the measured spin policy starts from what the last region learned
            home, until_probe, backoff, spinning_ns, sleeping_ns = _LEARNED
            _POLICY_STRUCT.pack_into(self._map, _OFF_DRIVER_POLICY, 0, 0, 0, 0, 0, home, home, until_probe, backoff,
                                     spinning_ns, sleeping_ns, 0, 0, 0, 0)

    def handed_over(self) -> None:
        """Close this process's descriptor (after the firmware inherited it)."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None

    def close(self) -> None:
        """Unmap the region (idempotent); its address must not be used afterwards."""
        global _LEARNED
        self.handed_over()
        if self._map is not None:
            fields = _POLICY_STRUCT.unpack_from(self._map, _OFF_DRIVER_POLICY)
            if fields[2]:  # the policy ran (a measured spin): keep what it learned
                _LEARNED = (fields[5], fields[7], fields[8], fields[9], fields[10])
            self._map.close()
            self._map = None
            self.address = 0

    @property
    def closed(self) -> bool:
        return self._map is None

    def spun_s(self) -> tuple[float, float]:
        """(firmware, driver): the time each has spun so far waiting for the other [s] (part of its CPU time)."""
        if self._map is None:
            return (math.nan, math.nan)
        firmware_ns = struct.unpack_from("<Q", self._map, _OFF_FIRMWARE_SPIN_NS)[0]
        driver_ns = struct.unpack_from("<Q", self._map, _OFF_DRIVER_SPIN_NS)[0]
        return (firmware_ns * 1e-9, driver_ns * 1e-9)

    def spin_choices(self) -> SpinChoices | None:
        """The driver's measured spin policy so far (None once closed)."""
        if self._map is None:
            return None
        fields = _POLICY_STRUCT.unpack_from(self._map, _OFF_DRIVER_POLICY)
        return SpinChoices(steps_spinning=fields[11], steps_sleeping=fields[12], switches=fields[13],
                           probes=fields[14], step_ns_spinning=fields[9], step_ns_sleeping=fields[10],
                           sleeping_now=fields[5] == 1)

    def publish_state(self, packet: Any) -> None:
        """Publish a state packet (a buffer of 144 bytes)."""
        self._lib.aerobat_shm_publish_state(self.address, *_pointer(packet))

    def publish_rc(self, packet: bytes) -> None:
        """Publish an RC packet (40 bytes); the firmware takes the latest with the next state packet."""
        self._lib.aerobat_shm_publish_rc(self.address, *_pointer(packet))

    def wait_motor(self, block: Any, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the answer to the last state packet, into ``block`` (writable, its size)."""
        pointer, size = _pointer(block)
        return bool(self._lib.aerobat_shm_wait_motor(self.address, pointer, size, int(self.spin_s * 1e9),
                                                     int(timeout_s * 1e9)) == size)


def _pointer(buffer: Any) -> tuple[Any, int]:
    """(a pointer argument, size in bytes) of a contiguous buffer: bytes, bytearray or a numpy array."""
    if isinstance(buffer, bytes):
        return buffer, len(buffer)
    if hasattr(buffer, "ctypes"):  # numpy
        return ctypes.c_void_p(buffer.ctypes.data), int(buffer.nbytes)
    view = memoryview(buffer).cast("B")
    return (ctypes.c_char * view.nbytes).from_buffer(view), view.nbytes
