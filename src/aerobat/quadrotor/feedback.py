"""Onboard feedback mixed into the learned open-loop program (paper Sect. 11's outlook).

The learned parameters still define the maneuver: its program, and with it the
*reference* — the nominal model's flight of that program, sampled at
``reference_rate_hz`` and uploaded with it. While the program runs, the vehicle's
onboard loop (800 Hz) corrects its commands towards the reference using only what
it has at that moment:

- its **attitude estimate**: gyro integration (with the gyro's scale error, bias and
  latency), fused with the motion-capture attitude the supervisor relays over the
  radio (70 Hz, delayed, lossy), matched in time against a short history;
- the relayed **deviation from the reference** (position and velocity, fitted by the
  supervisor to the latest motion-capture samples minus the reference at their
  times), extrapolated to now; it is used only while it is fresh.

Schemes (:class:`FeedbackScheme`):

``none``
    The paper's pure open loop: commands are the program's, nothing else.
``attitude``
    Body-rate corrections ``K_att · log(q̂⁻¹ ⊗ q_ref)`` that hold the reference attitude.
``tracking``
    ``attitude`` plus translation: a correcting acceleration ``−K_p δp − K_d δv``,
    its thrust-axis part added to the collective and its perpendicular part turned
    into a tilt of the attitude reference (faded out at low collective, where a tilt
    moves nothing).

On the nominal model the reference *is* the flight, so every correction is zero: the
design model, the Jacobian and the update rules are the paper's, unchanged. Feedback
takes out what does not repeat (start offsets, gusts, motor jitter) and learning what
does.

Everything compiled here is allocation-free and ``inline="always"`` so a plant's
kernel compiles as one unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from enum import StrEnum
from typing import Any

import numba as nb
import numpy as np

from aerobat.core.bounds import Interval, OneOf, Span, bounded, validate
from aerobat.errors import ConfigError

__all__ = [
    "FEEDBACK_COLUMNS",
    "Feedback",
    "FeedbackGains",
    "FeedbackScheme",
    "HISTORY_TICKS",
    "OPEN_LOOP",
    "Reference",
    "as_feedback",
    "feedback_vector",
    "onboard_state",
    "reference_from_trajectory",
]


class FeedbackScheme(StrEnum):
    """What the onboard loop adds to the program's commands."""

    NONE = "none"
    ATTITUDE = "attitude"
    TRACKING = "tracking"

    @property
    def code(self) -> int:
        """The scheme's number in the compiled kernels."""
        return list(type(self)).index(self)

    @classmethod
    def parse(cls, text: str, *, where: str = "--feedback") -> FeedbackScheme:
        try:
            return cls(str(text).strip().lower())
        except ValueError:
            raise ConfigError(f"{where} = {text!r}: expected one of {', '.join(s.value for s in cls)}") from None


DEFAULT_SCHEME = FeedbackScheme.TRACKING
"""The scheme measured best (docs/results.md, 'Feedback'); ``none`` is the paper's open loop."""


_GAIN = Interval(low=0.0)
"""A gain or a limit of the onboard feedback: a finite number >= 0."""


@dataclass(frozen=True, kw_only=True)
class FeedbackGains:
    """Gains and limits of the onboard feedback (units in the names)."""

    attitude_gain_per_s: float = bounded(10.0, _GAIN)
    attitude_gain_spinning_per_s: float = bounded(20.0, _GAIN)
    yaw_gain_per_s: float = bounded(8.0, _GAIN)
    position_gain_per_s2: float = bounded(10.0, _GAIN)
    velocity_gain_per_s: float = bounded(5.0, _GAIN)
    max_acceleration_m_s2: float = bounded(5.0, _GAIN)
    max_tilt_rad: float = bounded(0.25, _GAIN)
    tilt_fade_collective_m_s2: tuple[float, float] = bounded(
        (3.0, 7.0), Span(Interval(low=0.0, unit="m/s²"), strict=True))
    """(low, high) with 0 <= low < high [m/s²]."""
    max_rate_correction_rad_s: float = bounded(6.0, _GAIN)
    attitude_fusion_gain: float = bounded(0.4, Interval(0.0, 1.0, closed="right"))
    max_estimate_age_s: float = bounded(0.06, _GAIN)
    reference_rate_hz: float = bounded(100.0, Interval(10.0, 2000.0, unit="Hz"))

    def __post_init__(self) -> None:
        validate(self)

    def to_table(self) -> dict[str, Any]:
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in fields(self)}


@dataclass(frozen=True)
class Feedback:
    """A feedback scheme with its gains: what a plant's onboard loop mixes into the program."""

    scheme: FeedbackScheme = bounded(DEFAULT_SCHEME, OneOf(FeedbackScheme))
    """A member, or its value as text (any case, spaces around it allowed)."""
    gains: FeedbackGains = field(default_factory=FeedbackGains)

    def __post_init__(self) -> None:
        if isinstance(self.scheme, str) and not isinstance(self.scheme, FeedbackScheme):
            object.__setattr__(self, "scheme", self.scheme.strip().lower())
        validate(self)
        if not isinstance(self.gains, FeedbackGains):
            raise ConfigError(f"feedback.gains: expected FeedbackGains, got {type(self.gains).__name__}")

    @property
    def enabled(self) -> bool:
        return self.scheme is not FeedbackScheme.NONE

    def to_table(self) -> dict[str, Any]:
        """``{"scheme", "gains"}``, JSON- and TOML-ready."""
        return {"scheme": self.scheme.value, "gains": self.gains.to_table()}

    @classmethod
    def from_table(cls, table: Any, *, source: str) -> Feedback:
        """Inverse of :meth:`to_table` (gains not given keep their defaults)."""
        from collections.abc import Mapping

        from aerobat.config import dataclass_from_table

        if not isinstance(table, Mapping) or "scheme" not in table:
            raise ConfigError(f"{source}: expected a feedback table with a scheme, got {table!r}")
        unknown = set(table) - {"scheme", "gains"}
        if unknown:
            raise ConfigError(f"{source}: unknown field(s) {', '.join(sorted(unknown))} (scheme, gains)")
        scheme = FeedbackScheme.parse(table["scheme"], where=f"{source}.scheme")
        gains = dataclass_from_table(FeedbackGains, table.get("gains") or {}, source=f"{source}.gains")
        return cls(scheme, gains)


OPEN_LOOP = Feedback(FeedbackScheme.NONE)
"""The paper's pure open loop."""


def as_feedback(value: Feedback | FeedbackScheme | str | None) -> Feedback:
    """A :class:`Feedback` from a feedback, a scheme or its name (default gains); None is the default."""
    if value is None:
        return Feedback()
    if isinstance(value, Feedback):
        return value
    if isinstance(value, str):
        return Feedback(FeedbackScheme.parse(value, where="feedback"))
    raise ConfigError(f"feedback = {value!r}: expected a Feedback or one of "
                      f"{', '.join(s.value for s in FeedbackScheme)}")


# flat gains vector for the kernels
G_SCHEME, G_ATT, G_YAW, G_KP, G_KD, G_AMAX, G_TILT, G_FADE_LO, G_FADE_HI, G_RATE, G_FUSE, G_AGE, G_REF_DT = range(13)
G_ATT_SPIN = 13
N_GAINS = 14


def feedback_vector(feedback: Feedback) -> np.ndarray:
    """The scheme and its gains as the flat vector the compiled kernels read."""
    g = feedback.gains
    v = np.zeros(N_GAINS)
    v[G_SCHEME] = feedback.scheme.code
    v[G_ATT] = g.attitude_gain_per_s
    v[G_YAW] = g.yaw_gain_per_s
    v[G_KP] = g.position_gain_per_s2
    v[G_KD] = g.velocity_gain_per_s
    v[G_AMAX] = g.max_acceleration_m_s2
    v[G_TILT] = g.max_tilt_rad
    v[G_FADE_LO], v[G_FADE_HI] = g.tilt_fade_collective_m_s2
    v[G_RATE] = g.max_rate_correction_rad_s
    v[G_FUSE] = g.attitude_fusion_gain
    v[G_AGE] = g.max_estimate_age_s
    v[G_REF_DT] = 1.0 / g.reference_rate_hz
    v[G_ATT_SPIN] = g.attitude_gain_spinning_per_s
    return v


# ------------------------------------------------------------------ reference

FEEDBACK_COLUMNS = 10
"""Reference columns: position (3) [m, relative to the start], velocity (3) [m/s], quaternion (w, x, y, z)."""


@dataclass(frozen=True)
class Reference:
    """The nominal flight of a program, sampled every ``dt_s`` from τ = 0 (uploaded with the program).

    ``samples`` is (M, 10): position relative to the start [m], velocity [m/s], attitude quaternion.
    """

    dt_s: float
    samples: np.ndarray

    @property
    def duration_s(self) -> float:
        return float((self.samples.shape[0] - 1) * self.dt_s)

    @staticmethod
    def empty() -> Reference:
        samples = np.zeros((1, FEEDBACK_COLUMNS))
        samples[0, 6] = 1.0
        return Reference(1.0, samples)


def reference_from_trajectory(times_s: np.ndarray, states: np.ndarray, rate_hz: float) -> Reference:
    """Sample a nominal trajectory (times from 0, states in aerobat's layout) at ``rate_hz``.

    Positions are taken relative to the first state, so the reference moves with the start.
    """
    times_s = np.asarray(times_s, dtype=float)
    states = np.asarray(states, dtype=float)
    dt = 1.0 / rate_hz
    n = int(math.floor((times_s[-1] - times_s[0]) / dt + 1e-9)) + 1
    grid = times_s[0] + dt * np.arange(n)
    out = np.empty((n, FEEDBACK_COLUMNS))
    for j in range(6):
        out[:, j] = np.interp(grid, times_s, states[:, j])
    out[:, 0:3] -= states[0, 0:3]
    # attitude: the sample at or just before each grid time, nlerp to the next
    k = np.clip(np.searchsorted(times_s, grid, side="right") - 1, 0, len(times_s) - 2)
    span = times_s[k + 1] - times_s[k]
    w = np.where(span > 0, (grid - times_s[k]) / np.where(span > 0, span, 1.0), 0.0)
    qa, qb = states[k, 6:10], states[k + 1, 6:10]
    qb = np.where((np.sum(qa * qb, axis=1) < 0)[:, None], -qb, qb)
    q = (1 - w)[:, None] * qa + w[:, None] * qb
    out[:, 6:10] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return Reference(dt, out)


# --------------------------------------------------------- onboard estimator

HISTORY_TICKS = 96
"""Onboard attitude history kept for matching relayed samples (120 ms at 800 Hz)."""

# onboard state vector: q̂ (4), relayed δp (3), δv (3), sample time, have-translation flag, history head
S_Q, S_DP, S_DV, S_TM, S_HAVE, S_HEAD = 0, 4, 7, 10, 11, 12
N_ONBOARD = 13


def onboard_state() -> tuple[np.ndarray, np.ndarray]:
    """A fresh onboard estimator (level, no relayed estimate) and its empty history (t, q)."""
    state = np.zeros(N_ONBOARD)
    state[S_Q] = 1.0
    history = np.zeros((HISTORY_TICKS, 5))
    history[:, 0] = -1e9
    history[:, 1] = 1.0
    return state, history


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _qmul(aw, ax, ay, az, bw, bx, by, bz):  # pragma: no cover - compiled
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _qexp(vx, vy, vz):  # pragma: no cover - compiled
    """Quaternion of the rotation vector v [rad]."""
    angle = math.sqrt(vx * vx + vy * vy + vz * vz)
    if angle < 1e-12:
        return 1.0, 0.5 * vx, 0.5 * vy, 0.5 * vz
    s = math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), s * vx, s * vy, s * vz


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _qlog(w, x, y, z):  # pragma: no cover - compiled
    """Rotation vector [rad] of a unit quaternion, the short way round."""
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return 2.0 * x, 2.0 * y, 2.0 * z
    k = 2.0 * math.atan2(s, w) / s
    return k * x, k * y, k * z


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def onboard_propagate(state, history, t, p, q, r, dt):  # pragma: no cover - compiled
    """Record (t, q̂), then integrate the gyro rates (p, q, r) [rad/s] over [t, t + dt] into q̂."""
    head = int(state[S_HEAD])
    history[head, 0] = t
    for i in range(4):
        history[head, 1 + i] = state[i]
    state[S_HEAD] = (head + 1) % history.shape[0]
    dw, dx, dy, dz = _qexp(p * dt, q * dt, r * dt)
    w, x, y, z = _qmul(state[0], state[1], state[2], state[3], dw, dx, dy, dz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    state[0] = w / n
    state[1] = x / n
    state[2] = y / n
    state[3] = z / n


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def onboard_receive(state, history, gains, t_sample, qm, dp, dv, has_translation):  # pragma: no cover
    """A relayed estimate arrives: fuse the attitude sampled at ``t_sample``; keep the deviation."""
    best = -1
    best_gap = 1e9
    for k in range(history.shape[0]):
        gap = abs(history[k, 0] - t_sample)
        if gap < best_gap:
            best_gap = gap
            best = k
    if best >= 0 and best_gap < 2e-3:
        hw = history[best, 1]
        hx = history[best, 2]
        hy = history[best, 3]
        hz = history[best, 4]
        # body-frame error at the sample time, a fraction of it as a world-frame correction
        ew, ex, ey, ez = _qmul(hw, -hx, -hy, -hz, qm[0], qm[1], qm[2], qm[3])
        vx, vy, vz = _qlog(ew, ex, ey, ez)
        a = gains[G_FUSE]
        cw, cx, cy, cz = _qexp(a * vx, a * vy, a * vz)
        tw, tx, ty, tz = _qmul(hw, hx, hy, hz, cw, cx, cy, cz)
        dw, dx, dy, dz = _qmul(tw, tx, ty, tz, hw, -hx, -hy, -hz)  # δ = h ⊗ c ⊗ h⁻¹
        w, x, y, z = _qmul(dw, dx, dy, dz, state[0], state[1], state[2], state[3])
        n = math.sqrt(w * w + x * x + y * y + z * z)
        state[0] = w / n
        state[1] = x / n
        state[2] = y / n
        state[3] = z / n
        for k in range(history.shape[0]):
            w, x, y, z = _qmul(dw, dx, dy, dz, history[k, 1], history[k, 2], history[k, 3], history[k, 4])
            n = math.sqrt(w * w + x * x + y * y + z * z)
            history[k, 1] = w / n
            history[k, 2] = x / n
            history[k, 3] = y / n
            history[k, 4] = z / n
    if has_translation:
        for i in range(3):
            state[S_DP + i] = dp[i]
            state[S_DV + i] = dv[i]
        state[S_TM] = t_sample
        state[S_HAVE] = 1.0


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def reference_at(ref, dt, tau, out):  # pragma: no cover - compiled
    """Linear (position, velocity) and normalized-linear (attitude) interpolation of the reference."""
    m = ref.shape[0]
    u = tau / dt
    if u <= 0.0:
        j = 0
        f = 0.0
    elif u >= m - 1:
        j = m - 2 if m >= 2 else 0
        f = 1.0 if m >= 2 else 0.0
    else:
        j = int(math.floor(u))
        f = u - j
    jn = j + 1 if m >= 2 else j
    for i in range(6):
        out[i] = ref[j, i] + f * (ref[jn, i] - ref[j, i])
    dot = 0.0
    for i in range(6, 10):
        dot += ref[j, i] * ref[jn, i]
    sign = -1.0 if dot < 0.0 else 1.0
    n = 0.0
    for i in range(6, 10):
        out[i] = (1.0 - f) * ref[j, i] + f * sign * ref[jn, i]
        n += out[i] * out[i]
    n = math.sqrt(n)
    for i in range(6, 10):
        out[i] /= n


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def apply_feedback(cmd, state, gains, ref, tau, t, scratch):  # pragma: no cover - compiled
    """Add the scheme's corrections to ``cmd`` (collective, p̂, q̂, r̂) at maneuver time ``tau``.

    ``scratch`` is a length-10 work array for the reference sample.
    """
    scheme = int(gains[G_SCHEME])
    if scheme == 0:
        return
    reference_at(ref, gains[G_REF_DT], tau, scratch)
    qw = state[0]
    qx = state[1]
    qy = state[2]
    qz = state[3]
    # attitude error, body frame: q̂⁻¹ ⊗ q_ref
    ew, ex, ey, ez = _qmul(qw, -qx, -qy, -qz, scratch[6], scratch[7], scratch[8], scratch[9])
    phx, phy, phz = _qlog(ew, ex, ey, ez)
    # the attitude gain blends to its spinning value while the program commands fast rotation
    spin = math.sqrt(cmd[1] * cmd[1] + cmd[2] * cmd[2] + cmd[3] * cmd[3])
    still = min(max(1.0 - (spin - 1.0) / 2.0, 0.0), 1.0)
    k_att = still * gains[G_ATT] + (1.0 - still) * gains[G_ATT_SPIN]
    dc = 0.0
    if scheme == 2 and state[S_HAVE] > 0.0 and t - state[S_TM] <= gains[G_AGE]:
        age = t - state[S_TM]
        ax = -gains[G_KP] * (state[S_DP] + state[S_DV] * age) - gains[G_KD] * state[S_DV]
        ay = -gains[G_KP] * (state[S_DP + 1] + state[S_DV + 1] * age) - gains[G_KD] * state[S_DV + 1]
        az = -gains[G_KP] * (state[S_DP + 2] + state[S_DV + 2] * age) - gains[G_KD] * state[S_DV + 2]
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        if norm > gains[G_AMAX]:
            s = gains[G_AMAX] / norm
            ax *= s
            ay *= s
            az *= s
        # translation acts only while the reference is near upright: no tilt steering in a flip
        # and while the program commands no fast rotation (its motors are busy turning)
        upright = 1.0 - 2.0 * (scratch[7] * scratch[7] + scratch[8] * scratch[8])
        gate = min(max((upright - 0.5) / 0.4, 0.0), 1.0) * still
        ax *= gate
        ay *= gate
        az *= gate
        # thrust axis b3 = R(q̂) e_z (world)
        b3x = 2.0 * (qx * qz + qw * qy)
        b3y = 2.0 * (qy * qz - qw * qx)
        b3z = 1.0 - 2.0 * (qx * qx + qy * qy)
        along = ax * b3x + ay * b3y + az * b3z
        dc = along
        collective = cmd[0]
        lo = gains[G_FADE_LO]
        hi = gains[G_FADE_HI]
        fade = min(max((collective - lo) / (hi - lo), 0.0), 1.0) if gate > 0.0 else 0.0
        if fade > 0.0:
            px = ax - along * b3x
            py = ay - along * b3y
            pz = az - along * b3z
            # tilt (world) that turns c·b3 towards a⊥: δθ = b3 × a⊥ / c
            k = fade / max(collective, lo)
            tx = k * (b3y * pz - b3z * py)
            ty = k * (b3z * px - b3x * pz)
            tz = k * (b3x * py - b3y * px)
            tn = math.sqrt(tx * tx + ty * ty + tz * tz)
            if tn > gains[G_TILT]:
                s = gains[G_TILT] / tn
                tx *= s
                ty *= s
                tz *= s
            # to the body frame: R̂ᵀ δθ
            r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
            r01 = 2.0 * (qx * qy - qw * qz)
            r02 = 2.0 * (qx * qz + qw * qy)
            r10 = 2.0 * (qx * qy + qw * qz)
            r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
            r12 = 2.0 * (qy * qz - qw * qx)
            r20 = 2.0 * (qx * qz - qw * qy)
            r21 = 2.0 * (qy * qz + qw * qx)
            r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
            phx += r00 * tx + r10 * ty + r20 * tz
            phy += r01 * tx + r11 * ty + r21 * tz
            phz += r02 * tx + r12 * ty + r22 * tz
    lim = gains[G_RATE]
    cmd[0] += dc
    cmd[1] += min(max(k_att * phx, -lim), lim)
    cmd[2] += min(max(k_att * phy, -lim), lim)
    cmd[3] += min(max(gains[G_YAW] * phz, -lim), lim)


# ------------------------------------------------------------- supervisor side

RELAY_SAMPLES = 6
"""Motion-capture samples the supervisor fits the relayed deviation to (30 ms at 200 Hz)."""


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def relay_deviation(log, available, start_time, origin, ref, ref_dt, sample, out):  # pragma: no cover
    """Deviation from the reference at the latest motion-capture sample: line fit of (p − p_ref).

    ``log`` rows are (t, x, y, z, qw, qx, qy, qz); ``origin`` is the reference's start position;
    ``sample`` is a length-10 work array. ``out`` receives (δp (3) at the last sample, δv (3));
    returns False without samples.
    """
    if available <= 0:
        return False
    first = max(0, available - RELAY_SAMPLES)
    count = available - first
    last = available - 1
    t_last = log[last, 0]
    tm = 0.0
    for k in range(first, available):
        tm += log[k, 0] - t_last
    tm /= count
    den = 0.0
    for k in range(first, available):
        den += (log[k, 0] - t_last - tm) ** 2
    for i in range(3):
        out[i] = 0.0
        out[3 + i] = 0.0
    # out[0:3] collects the mean deviation, out[3:6] the covariance with time
    for k in range(first, available):
        reference_at(ref, ref_dt, log[k, 0] - start_time, sample)
        for i in range(3):
            out[i] += log[k, 1 + i] - origin[i] - sample[i]
    for i in range(3):
        out[i] /= count
    for k in range(first, available):
        reference_at(ref, ref_dt, log[k, 0] - start_time, sample)
        dtk = log[k, 0] - t_last - tm
        for i in range(3):
            out[3 + i] += dtk * (log[k, 1 + i] - origin[i] - sample[i] - out[i])
    for i in range(3):
        slope = out[3 + i] / den if den > 0.0 else 0.0
        out[3 + i] = slope
        out[i] -= slope * tm  # the fitted line at the last sample
    return True
