"""``aerobat vehicles``: the vehicle library, each preset's envelope and (``--flips``) the flips it allows."""

from __future__ import annotations

import argparse
import json
import math
import re
from typing import Any

from aerobat.cli.common import HelpFormatter, console
from aerobat.core.bounds import choices_of
from aerobat.quadrotor.maneuvers.flip import FLIPS, MAX_RATE_DEG_S, Axis

__all__ = ["register"]


def _parse_list(text: str, option: str, cast: Any, low: float, high: float) -> list[Any]:
    from aerobat.errors import ConfigError

    try:
        values = [cast(part) for part in str(text).split(",") if part.strip()]
    except ValueError:
        raise ConfigError(f"{option} {text!r}: expected a comma-separated list of numbers") from None
    if not values or not all(math.isfinite(v) and low <= v <= high for v in values):
        raise ConfigError(f"{option} {text!r}: every value must be in [{low:g}, {high:g}]")
    return values


def _cmd_vehicles(args: argparse.Namespace) -> int:
    from aerobat.experiments.vehicles import flip_feasibility, vehicle_envelope, vehicle_library
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    configs = vehicle_library() + [vehicle_from_name_or_file(path) for path in args.vehicle or []]
    flips = _parse_list(args.flip_counts, "--flip-counts", int, *FLIPS.bounds())
    rates = _parse_list(args.rates_deg_s, "--rates-deg-s", float, *MAX_RATE_DEG_S.bounds())
    rows = []
    for config in configs:
        row = vehicle_envelope(config)
        if args.flips:
            row["flips"] = [f.to_table() for f in flip_feasibility(config, flips, rates, axis=args.axis)]
        rows.append(row)
    if args.json:
        print(json.dumps(rows))
        return 0
    _print_envelopes(rows)
    if args.flips:
        for row in rows:
            _print_flips(row, rates)
    else:
        console().print("which flips each can fly: aerobat vehicles --flips (a design per flip, about a minute)")
    return 0


def _print_envelopes(rows: list[dict[str, Any]]) -> None:
    from rich.table import Table

    table = Table(title="vehicles (--vehicle NAME); envelope of the nominal model")
    for name, justify in (("name", "left"), ("mass [kg]", "right"), ("T/W", "right"), ("β̲ / β̄ [m/s²]", "right"),
                          ("β̲ / β̄ [g]", "right"), ("max roll / pitch acc. [°/s²]", "right"),
                          ("motor rates [1/s]", "right")):
        table.add_column(name, justify=justify)  # type: ignore[arg-type]
    for r in rows:
        table.add_row(r["name"], f"{r['mass_kg']:.3g}", f"{r['thrust_to_weight']:.2f}",
                      f"{r['collective_reduced_min_m_s2']:.2f} / {r['collective_reduced_max_m_s2']:.2f}",
                      f"{r['collective_reduced_min_g']:.2f} / {r['collective_reduced_max_g']:.2f}",
                      f"{math.degrees(r['max_roll_acceleration_rad_s2']):.0f} / "
                      f"{math.degrees(r['max_pitch_acceleration_rad_s2']):.0f}",
                      f"{r['motor_rate_up_per_s']:.3g} / {r['motor_rate_down_per_s']:.3g}")
    out = console()
    out.print(table)
    for r in rows:
        out.print(f"  {r['name']}: {r['summary'] or 'no [source] given'}"
                  + ("; with identified effects beyond the paper's model" if r["effects"] else ""))


def _print_flips(row: dict[str, Any], rates: list[float]) -> None:
    from rich.table import Table

    out = console()
    table = Table(title=f"{row['name']}: 2D flips designed on its nominal model (✓ duration, ✗ why not)")
    table.add_column("flips", justify="right")
    for rate in rates:
        table.add_column(f"{rate:g}°/s", justify="left")
    by_count: dict[int, list[dict[str, Any]]] = {}
    for f in row["flips"]:
        by_count.setdefault(f["flips"], []).append(f)
    reasons = []
    for count, cells in sorted(by_count.items()):
        texts = []
        for f in cells:
            if f["feasible"]:
                texts.append(f"✓ {f['duration_s']:.2f} s")
            else:
                reasons.append(f"{count} × {f['max_rate_deg_s']:g}°/s: {_in_degrees(f['reason'])}")
                texts.append(f"✗ ({len(reasons)})")
        table.add_row(str(count), *texts)
    out.print(table)
    for k, reason in enumerate(reasons, start=1):
        out.print(f"  ({k}) {reason}")


def _in_degrees(text: str) -> str:
    """A design's words with its angles in degrees, as the grid's rates: ``flip_angle = -18.8 rad`` → ``-1077°``."""
    def convert(match: re.Match[str]) -> str:
        value = math.degrees(float(match.group(1)))
        return f"{value:.0f}°/s" if match.group(2) else f"{value:.0f}°"

    return re.sub(r"([-+−]?\d+(?:\.\d+)?(?:e[-+]?\d+)?) rad(/s)?(?![/\w²])", convert, text.replace("−", "-"))


def register(sub: Any) -> None:
    p = sub.add_parser("vehicles", help="the vehicle library: presets, their envelopes and the flips they allow",
                       formatter_class=HelpFormatter)
    p.add_argument("--flips", action="store_true", help="design a grid of 2D flips on each vehicle (feasibility)")
    p.add_argument("--flip-counts", metavar="LIST", default="1,2,3", help="flip counts of the grid")
    p.add_argument("--rates-deg-s", metavar="LIST", default="720,1080,1440,1800",
                   help="coast rates of the grid [deg/s]")
    p.add_argument("--axis", choices=choices_of(Axis), default="roll", help="flip axis of the grid")
    p.add_argument("--vehicle", action="append", metavar="FILE.toml",
                   help="also list this vehicle file (repeatable), e.g. an identified one (default: the presets only)")
    p.add_argument("--json", action="store_true", help="print one JSON array")
    p.set_defaults(func=_cmd_vehicles)
