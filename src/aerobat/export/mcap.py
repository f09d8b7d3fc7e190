"""A stored session as an MCAP file that Foxglove's 3D and Plot panels (and PlotJuggler) open as they are.

Every trial with a measured trajectory becomes, on one timeline (trial after trial, a gap of
``GAP_S`` between them, starting at the session's start time):

* ``/trial/N/pose`` — ``foxglove.PoseInFrame`` in frame ``world`` (z up), one per measured sample;
* ``/tf`` — ``foxglove.FrameTransform`` ``world`` → ``body``, the same samples (the 3D panel
  draws the body's axes flying);
* ``/trial/N/state`` — JSON: velocity, body rates and the four rotor thrusts (plottable);
* ``/trial/N/command`` — JSON: the program's commands (collective, p̂, q̂, r̂) at each sample;
* ``/trials/state`` — JSON, every trial's samples on one channel, each with its ``trial`` and
  ``t_s`` (seconds since the program started): a Plot panel with ``t_s`` on its x-axis overlays
  the trials (position, velocity, rotation angles, rates, thrusts and commands);
* ``/scene`` — one ``foxglove.SceneUpdate`` at the start: every measured trial's path, the
  maneuver's start and target (:mod:`aerobat.export.mcap_scene`);
* ``/errors`` — JSON, one per stored trial (measured or not) at its end: status, every error
  component and the position error (with ``trial`` on the x-axis: the learning curve);
* ``/firmware`` — JSON, one per trial: what the plant recorded of its firmware (Betaflight: the
  firmware, arming, hover and frame counters);
* ``/trial/N/firmware`` — JSON, what the plant sampled inside itself, one message per sample, for
  a plant that has such signals (:class:`~aerobat.core.plant.Signals`, stored since schema 7;
  Betaflight: motors ``motor1..4``, the true rates ``rate_roll_deg_s``…, the set point
  ``setpoint_roll_deg_s``… and the PID terms ``p_roll``, ``i_roll``, ``d_roll``, ``f_roll``…,
  a sample per radio frame); ``/trials/firmware`` the same for every trial on one channel, each
  with its ``trial`` and ``t_s``, to overlay them.

A value a plant does not measure is null, never made up: the motion-capture plants (arena,
RotorPy, Betaflight, a flight controller) measure neither body rates nor rotor thrusts, only the
nominal plant (the design model flown) has them.

Foxglove's published protobuf schemas (``foxglove-schemas-protobuf``) are used for poses,
transforms and the scene, JSON Schema for the plottable channels, so no user has to write a layout.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.core.plant import Signals
from aerobat.errors import MissingDependency
from aerobat.export.mcap_scene import TrialPath, maneuver_marks, scene_update
from aerobat.fileio import atomic_output
from aerobat.store import Store
from aerobat.store.records import IterationRecord

__all__ = ["GAP_S", "McapSummary", "write_session_mcap"]

GAP_S = 1.0
"""Seconds between one trial's last sample and the next trial's first on the file's timeline."""

_STATE_COLUMNS = ((3, "vx_m_s"), (4, "vy_m_s"), (5, "vz_m_s"), (10, "p_rad_s"), (11, "q_rad_s"), (12, "r_rad_s"),
                  (13, "f1_n"), (14, "f2_n"), (15, "f3_n"), (16, "f4_n"))
"""State columns sent on ``/trial/N/state`` (a value the plant did not measure, e.g. the arena's thrusts, is null)."""
_COMMAND_COLUMNS = ((0, "collective_m_s2"), (1, "p_hat_rad_s"), (2, "q_hat_rad_s"), (3, "r_hat_rad_s"))
_ESTIMATED_RATES = ("p_est_rad_s", "q_est_rad_s", "r_est_rad_s")
"""Body rates estimated from the measured attitude (:func:`~aerobat.quadrotor.attitude_rates.body_rates_from_attitude`),
sent beside the measured ones: a plant that measures no rates (the arena's motion capture) still has them."""

_ANGLES = ("roll_rad", "pitch_rad", "yaw_rad")
"""Rotation angles about body x, y, z, unwrapped (:func:`~aerobat.quadrotor.dynamics.rotation_angles`: a triple
roll flip ends at 6π), from the measured attitude and its accumulated rotation."""
_POSITION = ((0, "x_m"), (1, "y_m"), (2, "z_m"))

_STATE_SCHEMA = {
    "type": "object", "title": "aerobat.TrialState",
    "properties": {"trial": {"type": "integer"}, "t_s": {"type": "number"},
                   **{k: {"type": ["number", "null"]} for _, k in _STATE_COLUMNS},
                   **{k: {"type": ["number", "null"], "description": "estimated from the measured attitude"}
                      for k in _ESTIMATED_RATES}}}
_COMMAND_SCHEMA = {
    "type": "object", "title": "aerobat.Command",
    "properties": {"trial": {"type": "integer"}, "t_s": {"type": "number"},
                   **{k: {"type": ["number", "null"]} for _, k in _COMMAND_COLUMNS}}}
_NULL_NUMBER = {"type": ["number", "null"]}
_OVERLAY_SCHEMA = {
    "type": "object", "title": "aerobat.TrialSample",
    "description": "every trial's samples on one channel: plot against t_s to overlay the trials",
    "properties": {"trial": {"type": "integer"},
                   "t_s": {"type": "number", "description": "seconds since the program started"},
                   **{k: _NULL_NUMBER for _, k in _POSITION}, **{k: _NULL_NUMBER for k in _ANGLES},
                   **{k: _NULL_NUMBER for _, k in _STATE_COLUMNS}, **{k: _NULL_NUMBER for k in _ESTIMATED_RATES},
                   **{k: _NULL_NUMBER for _, k in _COMMAND_COLUMNS}}}
_ERROR_SCHEMA = {"type": "object", "title": "aerobat.TrialError",
                 "properties": {"trial": {"type": "integer"}, "status": {"type": "string"},
                                "position_error_m": {"type": ["number", "null"]},
                                "error": {"type": "object"}, "message": {"type": "string"}}}
def _signals_schema(names: tuple[str, ...]) -> dict[str, Any]:
    """The JSON Schema of one sample of a plant's signals (its columns as they are named)."""
    return {"type": "object", "title": "aerobat.PlantSignals",
            "description": "what the plant sampled inside itself (a flight controller's motors, set point, PID terms)",
            "properties": {"trial": {"type": "integer"},
                           "t_s": {"type": "number", "description": "seconds since the program started"},
                           **{name: _NULL_NUMBER for name in names}}}


_FIRMWARE_SCHEMA = {"type": "object", "title": "aerobat.TrialPlantInfo",
                    "properties": {"trial": {"type": "integer"}, "plant": {"type": "string"},
                                   "info": {"type": "object"}}}


@dataclass(frozen=True)
class McapSummary:
    """What :func:`write_session_mcap` wrote: messages per topic and the time range [ns since 1970]."""

    path: Path
    session_id: int
    messages: dict[str, int]
    start_ns: int
    end_ns: int
    trials: tuple[int, ...]


def _epoch_ns(text: str) -> int:
    try:
        moment = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return 0
    return int(moment.timestamp()) * 1_000_000_000 + moment.microsecond * 1000


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _json_safe(value: Any) -> Any:
    """Plain JSON (non-finite numbers as null), as Foxglove's JSON decoder reads it."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, float):
        return _finite(value)
    return value if value is None or isinstance(value, str | int | bool) else str(value)


_CHUNK = 20
"""Trials read from the store at a time: a few trajectories in memory, never a whole session's."""


def _with_trajectories(store: Store, session_id: int, indices: list[int]) -> Iterator[IterationRecord]:
    """The session's iterations ``indices`` in order, with their trajectories, :data:`_CHUNK` at a time."""
    for k in range(0, len(indices), _CHUNK):
        yield from store.iterations(session_id, trajectories=True, plant_state=False, indices=indices[k:k + _CHUNK])


def _position_error_m(error: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(error[mask])) if mask.any() else math.nan


def _paths(store: Store, session_id: int, indices: list[int], mask: np.ndarray) -> list[TrialPath]:
    """Every measured trial's positions (the scene's first pass over the trajectories)."""
    return [TrialPath(it.index, np.asarray(it.states, dtype=np.float64)[:, 0:3].copy(), it.status.value,
                      _position_error_m(it.error, mask))
            for it in _with_trajectories(store, session_id, indices)
            if it.times_s is not None and it.states is not None and len(it.times_s)]


def write_session_mcap(store: Store, session_id: int, path: str | Path) -> McapSummary:
    """Write session ``session_id``'s trials to an MCAP file at ``path`` (see the module's description).

    Written by :func:`aerobat.fileio.atomic_output`: into a temporary file next to ``path`` that then
    replaces it, so a link at ``path`` is replaced (never written through), the store is never written
    (:class:`~aerobat.errors.ConfigError`), and a write that fails leaves the old file whole (a full
    disk is :class:`~aerobat.errors.DiskFull`). The trajectories are read twice, a few at a time:
    once for the scene (written first, at the start), once for the samples.
    """
    try:
        from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
        from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
        from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
        from mcap.writer import Writer
        from mcap_protobuf.schema import register_schema
    except ImportError as exc:
        raise MissingDependency(str(exc.name or "mcap"), extra="viewers", purpose="export --format mcap") from None
    from aerobat.core.registry import from_spec
    from aerobat.quadrotor.attitude_rates import body_rates_from_attitude
    from aerobat.quadrotor.dynamics import RATE_INT, rotation_angles

    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    maneuver = from_spec(mrec.spec, source=f"{store.path}: session {session_id} maneuver")
    mask = np.array(mrec.position_mask, dtype=bool)
    path = Path(path)
    counts: dict[str, int] = {}
    trials: list[int] = []
    start_ns = clock_ns = _epoch_ns(rec.started_at)
    first_ns: int | None = None
    last_ns = start_ns
    indices = [it.index for it in store.iterations(session_id)]
    paths = _paths(store, session_id, indices, mask)
    with atomic_output(path, option="--output", stores=(store.path,)) as stream:
        writer = Writer(stream)
        writer.start(profile="", library="aerobat")
        pose_schema = register_schema(writer, PoseInFrame)
        tf_schema = register_schema(writer, FrameTransform)
        scene_schema = register_schema(writer, SceneUpdate)
        json_schemas = {name: writer.register_schema(name=str(schema["title"]), encoding="jsonschema",
                                                     data=json.dumps(schema).encode())
                        for name, schema in (("state", _STATE_SCHEMA), ("command", _COMMAND_SCHEMA),
                                             ("overlay", _OVERLAY_SCHEMA), ("errors", _ERROR_SCHEMA),
                                             ("firmware", _FIRMWARE_SCHEMA))}
        channels: dict[str, int] = {}

        def channel(topic: str, schema_id: int, encoding: str) -> int:
            if topic not in channels:
                channels[topic] = writer.register_channel(topic=topic, message_encoding=encoding, schema_id=schema_id)
            return channels[topic]

        def emit(topic: str, schema_id: int, encoding: str, time_ns: int, data: bytes) -> None:
            nonlocal first_ns, last_ns
            writer.add_message(channel(topic, schema_id, encoding), log_time=time_ns, data=data,
                               publish_time=time_ns, sequence=counts.get(topic, 0))
            counts[topic] = counts.get(topic, 0) + 1
            first_ns = time_ns if first_ns is None else min(first_ns, time_ns)
            last_ns = max(last_ns, time_ns)

        def emit_json(topic: str, kind: str, time_ns: int, value: dict[str, Any]) -> None:
            emit(topic, json_schemas[kind], "json", time_ns, json.dumps(value, allow_nan=False).encode())

        def emit_signals(index: int, signals: Signals, first_s: float, t0: int) -> int:
            """A trial's signals, ``t0`` [ns] at ``first_s`` [s]; returns the last sample's time [ns]."""
            kind = f"signals:{','.join(signals.names)}"
            if kind not in json_schemas:
                schema = _signals_schema(signals.names)
                json_schemas[kind] = writer.register_schema(name=str(schema["title"]), encoding="jsonschema",
                                                            data=json.dumps(schema).encode())
            stamps = t0 + np.round((signals.times_s - first_s) * 1e9).astype(np.int64)
            for row, t, values in zip(stamps.tolist(), signals.times_s.tolist(), signals.values.tolist(),
                                      strict=True):
                sample = {"trial": index, "t_s": t, **{n: _finite(v) for n, v in zip(signals.names, values,
                                                                                      strict=True)}}
                emit_json(f"/trial/{index}/firmware", kind, row, sample)
                emit_json("/trials/firmware", kind, row, sample)
            return int(stamps[-1])

        if paths:
            scene = scene_update(paths, maneuver_marks(maneuver, mrec.position_mask), start_ns)
            emit("/scene", scene_schema, "protobuf", start_ns, scene.SerializeToString())
        del paths
        for it in _with_trajectories(store, session_id, indices):
            t0 = clock_ns
            if it.times_s is not None and it.states is not None and len(it.times_s):
                trials.append(it.index)
                times = np.asarray(it.times_s, dtype=np.float64)
                states = np.asarray(it.states, dtype=np.float64)
                commands = maneuver.program(it.params).commands_at(times)
                estimated = body_rates_from_attitude(times, states[:, 6:10])
                angles = (rotation_angles(states[:, :RATE_INT.stop]) if states.shape[1] >= RATE_INT.stop
                          else np.full((len(times), 3), np.nan))
                signals = it.signals if it.signals is not None and it.signals.times_s.size else None
                # the trial's first sample, measured or the plant's own (a firmware's frames start before the
                # program reaches it: the radio's latency), is the trial's start on the timeline
                first_s = float(times[0]) if signals is None else min(float(times[0]), float(signals.times_s[0]))
                stamps = t0 + np.round((times - first_s) * 1e9).astype(np.int64)
                for row, t, x, u, w, a in zip(stamps.tolist(), times.tolist(), states, commands, estimated, angles,
                                              strict=True):
                    pose = PoseInFrame(frame_id="world")
                    pose.timestamp.FromNanoseconds(row)
                    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = map(float, x[0:3])
                    q = pose.pose.orientation
                    q.w, q.x, q.y, q.z = map(float, x[6:10])
                    emit(f"/trial/{it.index}/pose", pose_schema, "protobuf", row, pose.SerializeToString())
                    tf = FrameTransform(parent_frame_id="world", child_frame_id="body")
                    tf.timestamp.FromNanoseconds(row)
                    tf.translation.x, tf.translation.y, tf.translation.z = map(float, x[0:3])
                    tf.rotation.w, tf.rotation.x, tf.rotation.y, tf.rotation.z = map(float, x[6:10])
                    emit("/tf", tf_schema, "protobuf", row, tf.SerializeToString())
                    state = {name: _finite(x[k]) for k, name in _STATE_COLUMNS}
                    rates = {name: _finite(w[k]) for k, name in enumerate(_ESTIMATED_RATES)}
                    command = {name: _finite(u[k]) for k, name in _COMMAND_COLUMNS}
                    emit_json(f"/trial/{it.index}/state", "state", row, {"trial": it.index, "t_s": t, **state,
                                                                          **rates})
                    emit_json(f"/trial/{it.index}/command", "command", row, {"trial": it.index, "t_s": t, **command})
                    emit_json("/trials/state", "overlay", row, {
                        "trial": it.index, "t_s": t, **{name: _finite(x[k]) for k, name in _POSITION},
                        **{name: _finite(a[k]) for k, name in enumerate(_ANGLES)}, **state, **rates, **command})
                end = int(stamps[-1])
                if signals is not None:
                    end = max(end, emit_signals(it.index, signals, first_s, t0))
            else:
                end = t0
            emit_json("/errors", "errors", end, {
                "trial": it.index, "status": it.status, "position_error_m": _finite(_position_error_m(it.error, mask)),
                "error": {n: _finite(v) for n, v in zip(mrec.error_names, it.error.tolist(), strict=True)},
                "message": it.message})
            emit_json("/firmware", "firmware", end, {"trial": it.index, "plant": rec.plant_kind,
                                                     "info": _json_safe(it.info)})
            clock_ns = end + int(GAP_S * 1e9)
        writer.finish()
    return McapSummary(path=path, session_id=session_id, messages=counts,
                       start_ns=start_ns if first_ns is None else first_ns, end_ns=last_ns, trials=tuple(trials))
