"""Printing a stored session: a header, a table of its iterations that reads at 80 columns, its parameters."""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.cli.common import console
from aerobat.core.maneuver import ErrorKind

__all__ = ["parameter_table", "print_stored_session"]


def parameter_table(mrec: Any, nominal: np.ndarray, learned: np.ndarray) -> Any:
    """The parameters with their meaning and unit, p⁰ and the learned values, and the change (a rich table);
    a learned value pinned at a bound (within 1e-4 of the parameter's scale) says so."""
    from rich.table import Table

    from aerobat.core.registry import parameters_of

    specs = parameters_of(mrec.spec, len(mrec.parameter_names))
    rows = Table(box=None, pad_edge=False, title=None)
    for name, justify in (("parameter", "left"), ("meaning", "left"), ("unit", "left"), ("p⁰", "right"),
                          ("learned", "right"), ("change", "right")):
        rows.add_column(name, justify=justify)  # type: ignore[arg-type]
    for k, (name, unit) in enumerate(zip(mrec.parameter_names, mrec.parameter_units, strict=True)):
        p0, p = float(nominal[k]), float(learned[k])
        side = specs[k].pinned(p) if specs else ""
        pinned = f" (at its {side} bound {specs[k].lower if side == 'lower' else specs[k].upper:g})" if side else ""
        rows.add_row(name, specs[k].description if specs else "", unit, f"{p0:.4g}", f"{p:.4g}{pinned}",
                     f"{p - p0:+.3g}")
    return rows


def print_stored_session(store: Any, session_id: int, *, iterations: bool, header: bool = False,
                         full: bool = False, table: bool = True) -> None:
    """Print a stored session; ``full`` adds one column per error component (wide); ``table=False``
    leaves out the per-iteration rows and keeps their summary."""
    from rich.table import Table

    from aerobat.experiments.designing import design_model_of

    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    out = console()
    if header:
        prec = store.plant(rec.plant_id)
        lines = [
            f"session {rec.id}: {mrec.name} on {prec.kind} (seed {rec.seed}, feedback "
            f"{(prec.config.get('feedback') or {}).get('scheme', 'none')}) — {rec.display_state}",
            f"  message:    {rec.message}",
            f"  started:    {rec.started_at}   updated: {rec.updated_at}   ended: {rec.ended_at or '—'}",
            f"  iterations: {rec.n_measured} measured of {rec.target_iterations} ({rec.n_records} trials, "
            f"last index {rec.last_index}, {rec.last_correction} corrections)",
            f"  rule:       {rec.rule.get('name')} with schedule {rec.rule.get('schedule')}",
            f"  design:     {drec.status}, residual {drec.residual_norm:.3g}, correction {drec.correction_kind}, "
            f"condition number {drec.condition_number:.3g}",
        ]
        kind, description = design_model_of(store.vehicle(drec.vehicle_id).config)
        lines.append(f"  designed on the {kind.value} model: {description}")
        lines.append(f"  vehicle:    {rec.vehicle}" + ("" if rec.plant_vehicle in ("", rec.vehicle) else
                                                       f" (the plant flew {rec.plant_vehicle})"))
        if rec.study_id is not None:
            lines.append(f"  study:      {rec.study_id}")
        if rec.warm_start_from is not None:
            lines.append(f"  warm start: from session {rec.warm_start_from}")
        if rec.last_position_error_m is not None:
            lines.append(f"  last position error: {rec.last_position_error_m:.4f} m")
        if rec.command:
            lines.append(f"  command:    aerobat {' '.join(rec.command)}")
        if rec.tags:
            lines.append(f"  tags:       {', '.join(rec.tags)}")
        lines += [f"  note:       {text} ({at[:16].replace('T', ' ')} UTC)" for at, text in rec.notes]
        for line in lines:
            out.print(line)
    if iterations:
        records = store.iterations(session_id)
        rows = Table(title=f"{mrec.name} on {rec.plant_kind}: {rec.display_state}")
        rows.add_column("i", justify="right")
        rows.add_column("status")
        rows.add_column("γ", justify="right")
        rows.add_column("scale", justify="right")
        position = np.array(mrec.position_mask, dtype=bool)
        angles = np.array([k is ErrorKind.ANGLE for k in mrec.error_kinds], dtype=bool)
        if full:
            for name, unit in zip(mrec.error_names, mrec.error_units, strict=True):
                rows.add_column(f"{name} [{'°' if unit == 'rad' else unit}]", justify="right")
        else:
            rows.add_column("position error [m]", justify="right")
            rows.add_column("largest angle error [°]", justify="right")
        for it in records:
            if not it.status.measured:
                cells = ["—"] * (len(mrec.error_names) if full else 2)
            elif full:
                cells = [f"{np.degrees(v):+.2f}" if unit == "rad" else f"{v:+.3f}"
                         for unit, v in zip(mrec.error_units, it.error, strict=True)]
            else:
                pos = float(np.linalg.norm(it.error[position])) if position.any() else float("nan")
                ang = float(np.degrees(np.max(np.abs(it.error[angles])))) if angles.any() else float("nan")
                cells = [f"{pos:.3f}", f"{ang:.2f}"]
            rows.add_row(str(it.index), it.status, f"{it.gamma:.2f}", f"{it.scale:.2f}", *cells)
        if table:
            out.print(rows)
        measured = [it for it in records if it.status.measured]
        if measured and position.any():
            errors = np.array([np.linalg.norm(it.error[position]) for it in measured])
            last = errors[-10:]
            out.print(f"position error: first {errors[0]:.3f} m, last {len(last)} mean {last.mean():.3f} m "
                      f"(std {last.std():.3f} m), best {errors.min():.3f} m")
    out.print(parameter_table(mrec, drec.p_nominal, rec.current_params))
    out.print(f"session {rec.id} {rec.display_state}: {rec.message}")
