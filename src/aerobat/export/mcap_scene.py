"""The ``/scene`` message of a session's MCAP file: every trial's measured path at once, the start and the target.

One ``foxglove.SceneUpdate`` holds an entity per measured trial (``trial/N``: its path as a line
strip in frame ``world`` and a sphere where it ended, coloured from blue, the first trial, to red,
the last) and one for the maneuver (``maneuver``: a white sphere at its start x(0), a green cube at
its target). It is one message, at the file's start: Foxglove's 3D panel keeps an entity until it
is replaced, and after a seek it shows the last message of each topic, so all paths stay drawn
wherever the timeline is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["ManeuverMarks", "TrialPath", "maneuver_marks", "scene_update", "trial_colour"]

FIRST_RGB = (0.15, 0.35, 1.0)
"""Colour of the first trial's path (blue); later trials shade towards :data:`LAST_RGB`."""
LAST_RGB = (1.0, 0.25, 0.1)
"""Colour of the last trial's path (red)."""
LINE_THICKNESS_PX = 2.0
END_SPHERE_M = 0.04
START_SPHERE_M = 0.06
TARGET_CUBE_M = 0.08
_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class TrialPath:
    """One measured trial as the scene draws it: positions [m] in frame ``world`` (z up), its status and error."""

    index: int
    positions_m: np.ndarray
    status: str
    position_error_m: float


@dataclass(frozen=True)
class ManeuverMarks:
    """Where the maneuver starts and ends [m], and which axes of the target its position errors fix.

    ``target_m`` is None when no position error measures one axis alone (a plug-in maneuver's
    error of a distance, say); an axis no error measures (a 2-D flip's x) takes the start's value.
    """

    start_m: np.ndarray
    target_m: np.ndarray | None
    target_axes: tuple[str, ...]


def maneuver_marks(maneuver: Any, position_mask: Sequence[bool]) -> ManeuverMarks:
    """The start x(0) and the target of ``maneuver``, read from its own functions.

    The target is found by moving the start 1 m and 2 m along each axis: a position error that
    grows by exactly that along one axis and no other measures that axis, and is zero at
    ``start - error(start)``.
    """
    mask = np.asarray(position_mask, dtype=bool)
    start = np.zeros(3)
    try:
        base = np.asarray(maneuver.initial_state(), dtype=np.float64).reshape(-1).copy()
        start[:min(3, base.size)] = base[:3]
        e0 = np.asarray(maneuver.error(base), dtype=np.float64).reshape(-1)
        if e0.shape != mask.shape:
            return ManeuverMarks(start, None, ())
        slopes = np.empty((3, e0.size))
        linear = np.ones(e0.size, dtype=bool)
        for axis in range(3):
            moved = [base.copy(), base.copy()]
            moved[0][axis] += 1.0
            moved[1][axis] += 2.0
            one, two = (np.asarray(maneuver.error(m), dtype=np.float64) - e0 for m in moved)
            slopes[axis] = one
            linear &= np.abs(two - 2.0 * one) < 1e-9
    except (ArithmeticError, ValueError, TypeError, IndexError, KeyError):
        return ManeuverMarks(start, None, ())
    target = start.copy()
    axes: list[str] = []
    for axis in range(3):
        for j in np.flatnonzero(mask & linear & np.isfinite(e0)):
            others = np.delete(slopes[:, j], axis)
            if abs(slopes[axis, j] - 1.0) < 1e-9 and np.all(np.abs(others) < 1e-9):
                target[axis] = start[axis] - e0[j]
                axes.append(_AXES[axis])
                break
    return ManeuverMarks(start, target if axes else None, tuple(axes))


def trial_colour(k: int, n: int) -> tuple[float, float, float]:
    """The colour (r, g, b in 0..1) of the ``k``-th of ``n`` measured trials: blue first, red last."""
    f = k / (n - 1) if n > 1 else 0.0
    return (FIRST_RGB[0] + f * (LAST_RGB[0] - FIRST_RGB[0]), FIRST_RGB[1] + f * (LAST_RGB[1] - FIRST_RGB[1]),
            FIRST_RGB[2] + f * (LAST_RGB[2] - FIRST_RGB[2]))


def _entity(scene: Any, entity_id: str, time_ns: int, metadata: dict[str, str]) -> Any:
    entity = scene.entities.add(id=entity_id, frame_id="world")
    entity.timestamp.FromNanoseconds(time_ns)  # lifetime 0: drawn until replaced
    for key, value in metadata.items():
        entity.metadata.add(key=key, value=value)
    return entity


def _place(primitive: Any, xyz: np.ndarray, size_m: float, rgb: tuple[float, float, float]) -> None:
    primitive.pose.position.x, primitive.pose.position.y, primitive.pose.position.z = map(float, xyz)
    primitive.pose.orientation.w = 1.0
    primitive.size.x = primitive.size.y = primitive.size.z = size_m
    primitive.color.r, primitive.color.g, primitive.color.b = rgb
    primitive.color.a = 1.0


def scene_update(paths: Sequence[TrialPath], marks: ManeuverMarks, time_ns: int) -> Any:
    """The ``foxglove.SceneUpdate`` of ``paths`` (in trial order) and the maneuver's ``marks``, stamped ``time_ns``."""
    from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    scene = SceneUpdate()
    for k, path in enumerate(paths):
        rgb = trial_colour(k, len(paths))
        error = "" if not np.isfinite(path.position_error_m) else f"{path.position_error_m:.6g}"
        entity = _entity(scene, f"trial/{path.index}", time_ns,
                         {"trial": str(path.index), "status": path.status, "position_error_m": error})
        line = entity.lines.add(type=LinePrimitive.Type.LINE_STRIP, thickness=LINE_THICKNESS_PX, scale_invariant=True)
        line.pose.orientation.w = 1.0
        line.color.r, line.color.g, line.color.b = rgb
        line.color.a = 1.0
        for x, y, z in np.asarray(path.positions_m, dtype=np.float64).tolist():
            line.points.add(x=x, y=y, z=z)
        if len(path.positions_m):
            _place(entity.spheres.add(), path.positions_m[-1], END_SPHERE_M, rgb)
    entity = _entity(scene, "maneuver", time_ns, {"target_axes": " ".join(marks.target_axes)})
    _place(entity.spheres.add(), marks.start_m, START_SPHERE_M, (1.0, 1.0, 1.0))
    if marks.target_m is not None:
        _place(entity.cubes.add(), marks.target_m, TARGET_CUBE_M, (0.1, 0.8, 0.2))
    return scene
