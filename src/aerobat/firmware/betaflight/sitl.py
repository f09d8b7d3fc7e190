"""Run one lockstep Betaflight SITL process and exchange packets with it.

:class:`SitlProcess` starts the patched SITL binary (see
``lockstep.patch`` in this package) in a private temporary directory with a
copy of a configured ``eeprom.bin``, on ports of its own, and drives it in
lockstep: every :meth:`SitlProcess.step` sends one state packet (preceded by an
RC packet when one is due) and waits for exactly one motor packet. The packets
travel over UDP or, with ``exchange=Exchange.SHM``, through a shared memory
region (:mod:`.shm`, a memfd the firmware inherits: ``BF_SITL_SHM_FD``); the
watchdog is the same for both.

Lifetime: the firmware never outlives its owner. It runs in its own process
group (so a kill reaches it alone), gets SIGKILL when the thread that started
it dies (``prctl(PR_SET_PDEATHSIG)``), exits by itself when its parent process
is gone (the patch checks ``getppid()`` while waiting), and is killed by
:meth:`SitlProcess.close`, the context manager, and a ``weakref.finalize``
finalizer that also runs at interpreter exit (``atexit``).

Note that PR_SET_PDEATHSIG is tied to the *thread* that forked: start the
SITL from a thread that lives as long as you need it (e.g. not from a
short-lived worker thread).
"""

from __future__ import annotations

import ctypes
import os
import shutil
import signal
import socket
import struct
import subprocess
import tempfile
import time
import weakref
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import FirmwareExited, FirmwareNotResponding, FirmwareUnavailable
from .link import FirmwareLink
from .packets import MOTOR_STRUCT, Exchange, SitlState, pack_rc, pack_state
from .ports import SitlPorts, allocate_ports
from .rc import RADIO_LOST_US, RC_CHANNEL_COUNT

if TYPE_CHECKING:
    from .shm import SpinChoices

__all__ = ["SitlPorts", "SitlProcess", "allocate_ports"]

_WORKDIR_PREFIX = "aerobat-betaflight-"
_OWNER_FILE = "owner"
_READY_MARK = "[SITL] lockstep: ready"
_BIND_FAILURE_MARKS = ("cannot bind", "failed!!")
_PR_SET_PDEATHSIG = 1
_START_ATTEMPTS = 3
_WATCHDOG_SLICE_S = 0.05


def _load_prctl() -> Callable[..., int] | None:
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _load_prctl()  # resolved before any fork: the child only calls it


def _child_setup(parent_pid: int) -> Callable[[], None]:
    """preexec_fn: SIGKILL the child when its parent (thread) dies."""

    def setup() -> None:
        if _PRCTL is not None:
            _PRCTL(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent_pid:  # the parent died before prctl took effect
            os._exit(1)

    return setup


def _process_identity(pid: int) -> str | None:
    """``"<pid> <start time>"`` of a live process (robust to pid reuse), None if there is none."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return None if fields[0] == "Z" else f"{pid} {fields[19]}"


def _sweep_stale_workdirs() -> None:
    """Remove working directories whose owner process is gone.

    An owner killed with SIGKILL cannot clean up (its firmware dies with it,
    through PR_SET_PDEATHSIG, but the directory stays); the next owner does it. A directory
    without its owner file yet is being set up by another process and is left alone.
    """
    for workdir in Path(tempfile.gettempdir()).glob(_WORKDIR_PREFIX + "*"):
        try:
            owner = (workdir / _OWNER_FILE).read_text().strip()
        except OSError:
            continue
        if _process_identity(int(owner.split()[0])) != owner:
            shutil.rmtree(workdir, ignore_errors=True)


def _tail(path: Path, lines: int = 25) -> str:
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return ""
    return "\n".join(text.splitlines()[-lines:])


class _Resources:
    """What must be released when a :class:`SitlProcess` goes away (no reference to it)."""

    def __init__(self) -> None:
        self.owner_pid = os.getpid()
        self.process: subprocess.Popen[bytes] | None = None
        self.sockets: list[socket.socket] = []
        self.shm: Any = None  # the shm.ShmRegion of a shared-memory exchange
        self.workdir: Path | None = None
        self.keep_workdir = False

    def kill(self) -> None:
        process, self.process = self.process, None
        if process is not None and os.getpid() == self.owner_pid and process.poll() is None:
            try:
                os.killpg(process.pid, signal.SIGTERM)
                os.killpg(process.pid, signal.SIGCONT)  # a stopped (hung) firmware takes the SIGTERM now
                process.wait(timeout=1.0)
            except ProcessLookupError:
                pass
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait(timeout=5.0)
        elif process is not None and process.poll() is not None:
            process.wait()

    def release(self) -> None:
        if os.getpid() != self.owner_pid:  # a forked child must not kill its parent's firmware
            return
        self.kill()
        for sock in self.sockets:
            sock.close()
        self.sockets.clear()
        if self.shm is not None:  # after the kill: the firmware no longer touches it
            self.shm.close()
            self.shm = None
        if self.workdir is not None and not self.keep_workdir:
            shutil.rmtree(self.workdir, ignore_errors=True)
        self.workdir = None


class SitlProcess:
    """One lockstep SITL instance.

    Parameters
    ----------
    binary : Path
        The lockstep SITL executable (:func:`.build.ensure_sitl`).
    eeprom : Path or None
        Configured ``eeprom.bin`` (:func:`.configure.ensure_eeprom`) to copy
        into the working directory; None starts from a blank eeprom.
    gyro_rate_hz : int
        The firmware's virtual gyro rate, which must equal the state packet
        rate (8000 like a real F7/H7 gyro, or 4000, 2000, ...).
    rc_rate_hz : float
        RC packets are sent every ``1 / rc_rate_hz`` of simulated time (the
        firmware sees them as receiver frames and measures this rate).
    step_timeout_s : float
        Wall-clock time a step waits for its motor packet before the
        watchdog raises :class:`FirmwareNotResponding`.
    start_timeout_s : float
        Wall-clock time to wait for the firmware to boot.
    keep_workdir : bool
        Keep the temporary directory (log, eeprom) after :meth:`close`.
    exchange : Exchange or str
        How the per-step packets travel: ``"udp"`` (sockets) or ``"shm"`` (shared memory).
    spin_us : float
        Shared memory only: the longest either side busy-waits for the other before it sleeps
        on a futex [us] (adaptive below it; 0: always sleep). The firmware gets it as
        ``BF_SITL_SHM_SPIN_US``.
    """

    def __init__(
        self,
        binary: Path,
        eeprom: Path | None,
        *,
        gyro_rate_hz: int = 8000,
        rc_rate_hz: float = 250.0,
        step_timeout_s: float = 2.0,
        start_timeout_s: float = 10.0,
        keep_workdir: bool = False,
        exchange: Exchange | str = Exchange.UDP,
        spin_us: float = 20.0,
    ) -> None:
        if 1_000_000 % gyro_rate_hz != 0 or not 500 <= gyro_rate_hz <= 8000:
            raise ValueError(f"gyro_rate_hz must divide 1e6 and be in 500..8000, got {gyro_rate_hz}")
        if not Path(binary).is_file():
            raise FirmwareUnavailable(f"SITL binary not found: {binary}")
        self.binary = Path(binary)
        self.eeprom = None if eeprom is None else Path(eeprom)
        self.gyro_rate_hz = gyro_rate_hz
        self.gyro_period_us = 1_000_000 // gyro_rate_hz
        self.rc_period_us = int(round(1e6 / rc_rate_hz))
        self.step_timeout_s = step_timeout_s
        self.start_timeout_s = start_timeout_s
        self.keep_workdir = keep_workdir
        try:
            self.exchange_kind = Exchange(exchange)
        except ValueError:
            raise ValueError(f"exchange = {exchange!r}: allowed 'udp' or 'shm'") from None
        if not 0.0 <= spin_us <= 1_000_000.0:
            raise ValueError(f"spin_us = {spin_us!r}: allowed 0 to 1e6")
        self.spin_us = float(spin_us)
        self._resources = _Resources()
        self._finalizer = weakref.finalize(self, self._resources.release)
        self._finalizer.atexit = True
        self._motor_buffer = bytearray(max(128, MOTOR_STRUCT.size))
        try:
            self._start()
        except BaseException:
            self._finalizer()
            raise

    # ------------------------------------------------------------------ lifetime

    def _start(self) -> None:
        resources = self._resources
        if not self._finalizer.alive:  # restarted after close()
            self._finalizer = weakref.finalize(self, resources.release)
            self._finalizer.atexit = True
        resources.keep_workdir = self.keep_workdir
        _sweep_stale_workdirs()
        resources.workdir = Path(tempfile.mkdtemp(prefix=_WORKDIR_PREFIX))
        # written whole under another name, then renamed: a sweep in another process never reads it half written
        partial = resources.workdir / (_OWNER_FILE + ".partial")
        partial.write_text(f"{_process_identity(os.getpid())}\n")  # internal
        os.replace(partial, resources.workdir / _OWNER_FILE)
        if self.eeprom is not None:
            shutil.copyfile(self.eeprom, resources.workdir / "eeprom.bin")
        self.log_path = resources.workdir / "sitl.log"
        for attempt in range(_START_ATTEMPTS):
            ports, motor_socket = allocate_ports()
            self.ports = ports
            resources.sockets = [motor_socket]
            env = dict(
                os.environ,
                BF_SITL_UDP_BASE_PORT=str(ports.udp_base),
                BF_SITL_TCP_BASE_PORT=str(ports.tcp_base),
                BF_SITL_GYRO_RATE_HZ=str(self.gyro_rate_hz),
            )
            env.pop("BF_SITL_SHM_FD", None)
            pass_fds: tuple[int, ...] = ()
            if self.exchange_kind is Exchange.SHM:
                from .shm import ShmRegion

                resources.shm = ShmRegion(spin_s=self.spin_us * 1e-6)
                pass_fds = (resources.shm.fd,)
                env["BF_SITL_SHM_FD"] = str(resources.shm.fd)
                env["BF_SITL_SHM_SPIN_US"] = str(round(self.spin_us))
            with open(self.log_path, "wb") as log:  # internal
                resources.process = subprocess.Popen(
                    [str(self.binary), "127.0.0.1"],
                    cwd=resources.workdir,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                    preexec_fn=_child_setup(os.getpid()),
                    pass_fds=pass_fds,
                )
            if resources.shm is not None:
                resources.shm.handed_over()
            if self._wait_ready():
                break
            resources.kill()
            motor_socket.close()
            if resources.shm is not None:
                resources.shm.close()
                resources.shm = None
            log_tail = _tail(self.log_path)
            if attempt + 1 == _START_ATTEMPTS or not any(mark in log_tail for mark in _BIND_FAILURE_MARKS):
                raise FirmwareNotResponding("the SITL firmware did not start", log_tail, str(self.log_path))
        motor_socket.setsockopt(
            socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", 0, int(_WATCHDOG_SLICE_S * 1e6))
        )
        self._motor_socket = motor_socket
        # Blocking sockets with kernel timeouts (SO_*TIMEO): one syscall per packet, never stuck.
        self._state_socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._state_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, struct.pack("ll", 1, 0))
        self._state_socket.connect(("127.0.0.1", ports.state_port))
        self._rc_socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._rc_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, struct.pack("ll", 1, 0))
        self._rc_socket.connect(("127.0.0.1", ports.rc_port))
        resources.sockets += [self._state_socket, self._rc_socket]
        self._shm = resources.shm
        self._rc_channels_us: tuple[int, ...] = RADIO_LOST_US
        self._rc_set = False
        self._next_rc_us: int | None = None
        self._last_time_us: int | None = None
        self.steps = 0

    def _wait_ready(self) -> bool:
        """Wait for the firmware's ready line; False if it exited first."""
        process = self._resources.process
        assert process is not None
        deadline = time.monotonic() + self.start_timeout_s
        pause_s = 0.0005  # the firmware is ready in ~10 ms: look often at first, then every 10 ms
        while time.monotonic() < deadline:
            if _READY_MARK in _tail(self.log_path, 200):
                return True
            if process.poll() is not None:
                return False
            time.sleep(pause_s)
            pause_s = min(0.01, 2 * pause_s)
        raise FirmwareNotResponding(
            f"the SITL firmware did not get ready within {self.start_timeout_s} s",
            _tail(self.log_path),
            str(self.log_path),
        )

    @property
    def pid(self) -> int | None:
        """Process id of the firmware (None once closed)."""
        process = self._resources.process
        return None if process is None else process.pid

    @property
    def workdir(self) -> Path | None:
        """The instance's private working directory (None once closed and removed)."""
        return self._resources.workdir

    def alive(self) -> bool:
        """Whether the firmware process is running."""
        process = self._resources.process
        return process is not None and process.poll() is None

    def close(self) -> None:
        """Kill the firmware (SIGTERM to its process group, then SIGKILL) and release everything."""
        self._finalizer()

    def restart(self) -> None:
        """Close and start a fresh instance from the same binary and eeprom (new ports, new clock)."""
        self._resources.release()
        try:
            self._start()
        except BaseException:
            self._finalizer()
            raise

    def __enter__(self) -> SitlProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ exchange

    def set_rc(self, channels_us: Sequence[int]) -> None:
        """Set the RC channels (16, microseconds, AETR1234) sent from now on at ``rc_rate_hz``.

        Use :data:`.rc.RADIO_LOST_US` for a lost radio. Until the first call,
        no RC packet is sent (the firmware reports RXLOSS).
        """
        channels = tuple(int(value) for value in channels_us)
        if len(channels) != RC_CHANNEL_COUNT:
            raise ValueError(f"expected {RC_CHANNEL_COUNT} channels, got {len(channels)}")
        self._rc_channels_us = channels
        self._rc_set = True

    def step(self, state: SitlState) -> tuple[float, float, float, float]:
        """Send one state packet (and an RC packet when due) and return the motor packet.

        Parameters
        ----------
        state : SitlState
            The simulated sensors at ``state.time_s``, a multiple of the gyro
            period and normally one period after the previous step (the
            firmware's gyro task runs once per packet; its filters and PID
            assume that period).

        Returns
        -------
        tuple of 4 float
            Motor commands in [0, 1], packet order (see :mod:`.packets`).

        Raises
        ------
        FirmwareExited
            The firmware process is gone.
        FirmwareNotResponding
            No motor packet within ``step_timeout_s``; restart the instance.
        """
        return self.step_packed(state.time_s, pack_state(state))

    def step_packed(self, time_s: float, state_packet: bytes) -> tuple[float, float, float, float]:
        """:meth:`step` for an already packed 144-byte state packet whose timestamp is ``time_s``."""
        time_us = int(round(time_s * 1e6))
        if self._last_time_us is not None and time_us <= self._last_time_us:
            raise ValueError(f"state time must increase: {time_us} us after {self._last_time_us} us")
        if time_us % self.gyro_period_us:
            raise ValueError(f"state time {time_us} us is not a multiple of the gyro period {self.gyro_period_us} us")
        self._last_time_us = time_us
        try:
            if self._rc_set and (self._next_rc_us is None or time_us >= self._next_rc_us):
                self._send_rc_packet(pack_rc(time_s, self._rc_channels_us))
                self._next_rc_us = time_us + self.rc_period_us
            self._send_state(state_packet)
        except OSError as error:  # refused (firmware gone) or send timeout
            self._check_alive()
            raise FirmwareNotResponding(f"cannot send to the firmware: {error}", _tail(self.log_path)) from error
        motors = self._receive_motors()
        self.steps += 1
        return motors

    def send_rc(self, channels_us: Sequence[int]) -> None:
        """Send one RC frame now (it reaches the firmware with the next state packet).

        For a caller that schedules frames itself (frame rate, loss, latency); do not mix with
        :meth:`set_rc`, which sends periodically from :meth:`step`.
        """
        try:
            self._send_rc_packet(pack_rc(0.0, tuple(int(value) for value in channels_us)))
        except OSError as error:
            self._check_alive()
            raise FirmwareNotResponding(f"cannot send to the firmware: {error}", _tail(self.log_path)) from error

    def exchange(self, state_packet: Any, motors: Any) -> None:
        """Send a packed 144-byte state packet and receive the answering firmware packet into ``motors``.

        The fast path of :meth:`step_packed` for a caller that keeps its own clock (no time
        checks): ``motors`` is any writable buffer of the firmware packet's size
        (:data:`~.packets.MOTOR_STRUCT`, 76 bytes: a float32 array of 19 gets the motor commands, then the
        set point and the PID terms). Same watchdog and errors as :meth:`step`.
        """
        try:
            self._send_state(state_packet)
        except OSError as error:
            self._check_alive()
            raise FirmwareNotResponding(f"cannot send to the firmware: {error}", _tail(self.log_path)) from error
        self.receive_into(motors)

    def _send_state(self, state_packet: Any) -> None:
        if self._shm is not None:
            self._check_open()
            self._shm.publish_state(state_packet)
        else:
            self._state_socket.send(state_packet)

    def _send_rc_packet(self, rc_packet: bytes) -> None:
        if self._shm is not None:
            self._check_open()
            self._shm.publish_rc(rc_packet)
        else:
            self._rc_socket.send(rc_packet)

    def _check_open(self) -> None:
        if self._shm.closed:
            self._raise_dead()

    def receive_into(self, block: Any) -> None:
        """Receive the firmware packet answering the state packet just sent into ``block`` (its size).

        Waits in slices of the motor socket's receive timeout, checking the process in between;
        packets of another size are skipped.

        Raises
        ------
        FirmwareExited
            The firmware process is gone.
        FirmwareNotResponding
            No packet within ``step_timeout_s``.
        """
        view = memoryview(block).cast("B")
        if self._shm is not None:
            self._check_open()
            if self._shm.wait_motor(block, _WATCHDOG_SLICE_S):
                self.steps += 1
                return
        else:
            try:
                if self._motor_socket.recv_into(view, view.nbytes, socket.MSG_TRUNC) == view.nbytes:
                    self.steps += 1
                    return
            except (BlockingIOError, TimeoutError):
                pass
        # slow path: the watchdog (and any stray datagram)
        size = self._wait_for_packet()
        view[:] = self._motor_buffer[:size]
        self.steps += 1

    @property
    def shm_address(self) -> int | None:
        """Address of the shared-memory region in this process (None for the UDP exchange), for a compiled loop.

        Valid until :meth:`close`. After a failed exchange, finish it with :meth:`exchange` or
        :meth:`receive_into`, which apply the watchdog.
        """
        return None if self._shm is None or self._shm.closed else int(self._shm.address)

    @property
    def socket_fds(self) -> tuple[int, int]:
        """(state socket, motor socket) file descriptors, for a compiled exchange loop (the lockstep plant's).

        The state socket is connected to the firmware (``send``); the motor socket has a kernel
        receive timeout (``recv`` returns within it). After a failed exchange, finish it with
        :meth:`exchange` or :meth:`receive_into`, which apply the watchdog.
        """
        return self._state_socket.fileno(), self._motor_socket.fileno()

    @property
    def rc_socket_fd(self) -> int:
        """The RC socket's file descriptor (connected to the receiver; sends time out), for a compiled frame loop.

        After a failed send, send the frame with :meth:`send_rc`, which raises the right error.
        """
        return self._rc_socket.fileno()

    def spun_s(self) -> tuple[float, float]:
        """(firmware, driver): time each side has spun so far waiting for the other [s]; zeros over UDP.

        The shared-memory waits spin before they sleep, and the spinning is CPU time: the
        firmware's work is :meth:`cpu_time_s` minus its part here. NaN once closed.
        """
        if self._shm is None:
            return (0.0, 0.0)
        return self._shm.spun_s()

    def spin_choices(self) -> SpinChoices | None:
        """The driver's measured spin policy so far (:class:`~.shm.SpinChoices`); None over UDP or once closed."""
        return None if self._shm is None else self._shm.spin_choices()

    def cpu_time_s(self) -> float | None:
        """CPU time the firmware process has used so far [s] (``/proc/<pid>/schedstat``); None if unknown."""
        process = self._resources.process
        if process is None:
            return None
        try:
            return int(Path(f"/proc/{process.pid}/schedstat").read_text().split()[0]) * 1e-9
        except (OSError, ValueError, IndexError):
            return None

    def _receive_motors(self) -> tuple[float, float, float, float]:
        self._wait_for_packet()
        m0, m1, m2, m3 = struct.unpack_from("<4f", self._motor_buffer)  # the motors lead the packet
        return (m0, m1, m2, m3)

    def _wait_for_packet(self) -> int:
        """Receive the next firmware packet into ``_motor_buffer`` (watchdog); returns its size."""
        buffer = self._motor_buffer
        deadline: float | None = None
        shm_block = memoryview(buffer)[: MOTOR_STRUCT.size]
        while True:
            try:
                if self._shm is not None:
                    self._check_open()
                    if not self._shm.wait_motor(shm_block, _WATCHDOG_SLICE_S):
                        raise TimeoutError
                    return MOTOR_STRUCT.size
                size = self._motor_socket.recv_into(buffer, len(buffer), socket.MSG_TRUNC)
            except (BlockingIOError, TimeoutError):
                self._check_alive()
                now = time.monotonic()
                if deadline is None:
                    deadline = now + self.step_timeout_s - _WATCHDOG_SLICE_S
                elif now > deadline:
                    raise FirmwareNotResponding(
                        f"no motor packet within {self.step_timeout_s} s (step {self.steps})",
                        _tail(self.log_path),
                        str(self.log_path),
                    ) from None
                continue
            if size == MOTOR_STRUCT.size:
                return size

    def _check_alive(self) -> None:
        process = self._resources.process
        if process is None or process.poll() is not None:
            self._raise_dead()

    def _raise_dead(self) -> None:
        process = self._resources.process
        returncode = -1 if process is None or process.returncode is None else process.returncode
        raise FirmwareExited(returncode, _tail(self.log_path), str(self.log_path))

    def open_link(self, connect_timeout_s: float = 5.0) -> FirmwareLink:
        """Open an MSP/CLI link to UART1.

        For diagnosis only: MSP/CLI traffic reaches the firmware at wall-clock
        moments (non-deterministic), and entering the CLI blocks arming for the
        rest of the process. The firmware only answers while it is stepped.
        """
        return FirmwareLink.connect_tcp(self.ports.uart1_port, connect_timeout_s=connect_timeout_s)
