"""The battery under load from real logs (issue 42): the numbers docs/plants.md quotes.

Run (needs ../shared/data; a few seconds):

    .venv/bin/python scripts/results_battery.py
    .venv/bin/python scripts/results_battery.py --json

For each flight of the ROMA F5 (6S) and the Gecko (4S) alone: the pack's resting voltage, its sag at
full load and how much of the logged voltage that explains (:func:`aerobat.quadrotor.identification.
battery.fit_battery`). Then the check that matters for a twin: flight 1's sag, with flights 2 and 3's
own resting voltage and drain refitted, against their logged voltage (R² and rms), beside the constant
voltage a model without a battery assumes (its R² is 0 by construction: the mean).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LOGS = ROOT.parent / "shared" / "data" / "flight-logs" / "betaflight"
FLIGHTS = (("diatone-roma-f5.bbl", 1), ("diatone-roma-f5.bbl", 2), ("diatone-roma-f5.bbl", 3), ("aikonf7-gecko.bbl", 1))


def _series(name: str, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from aerobat.logs import read_log
    from aerobat.quadrotor.flightlog import Channel

    log = read_log(LOGS / name, index)
    motors = log.signals[Channel.MOTOR_COMMAND]
    return motors.time_s, log.signals[Channel.BATTERY_VOLTAGE].at(motors.time_s)[:, 0], motors.values


def _held_sag(series: tuple[np.ndarray, np.ndarray, np.ndarray], sag_v: float) -> dict[str, float]:
    """Refit rest and drain with the sag held: R² and rms of the logged voltage (flying samples)."""
    from aerobat.experiments.log_replay import FLYING_MOTOR

    t, v, u = series
    u = np.clip(u, 0.0, 1.0)
    ok = np.isfinite(v) & (v > 0) & (u.mean(axis=1) > FLYING_MOTOR)
    t, v, load = t[ok], v[ok], (u[ok] ** 2).mean(axis=1)
    design = np.column_stack([np.ones(t.size), -(t - np.median(t))])
    coef, *_ = np.linalg.lstsq(design, v + sag_v * load, rcond=None)
    residual = v - (design @ coef - sag_v * load)
    return {"r_squared": float(1.0 - np.var(residual) / np.var(v)), "rms_v": float(np.sqrt(np.mean(residual**2)))}


def _forms(series: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict[str, float]:
    """R² of the rest + drain + sag fit with other loads: mean(u), mean(u^1.5), mean(u²), and mean(u²) lagged."""
    from aerobat.experiments.log_replay import FLYING_MOTOR

    t, v, u = series
    u = np.clip(u, 0.0, 1.0)
    ok = np.isfinite(v) & (v > 0) & (u.mean(axis=1) > FLYING_MOTOR)
    out = {}
    loads = {"u": u.mean(axis=1), "u^1.5": (u**1.5).mean(axis=1), "u^2": (u**2).mean(axis=1)}
    for lag_s in (0.02, 0.05, 0.1):  # a first-order lag between the load and the voltage
        lagged = loads["u^2"].copy()
        a = np.exp(-np.diff(t, prepend=t[0]) / lag_s)
        for k in range(1, lagged.size):
            lagged[k] = a[k] * lagged[k - 1] + (1.0 - a[k]) * loads["u^2"][k]
        loads[f"u^2 lagged {lag_s * 1e3:.0f} ms"] = lagged
    for name, load in loads.items():
        design = np.column_stack([np.ones(ok.sum()), -(t[ok] - np.median(t[ok])), -load[ok]])
        coef, *_ = np.linalg.lstsq(design, v[ok], rcond=None)
        out[name] = float(1.0 - np.var(v[ok] - design @ coef) / np.var(v[ok]))
    return out


def run() -> dict[str, Any]:
    """Every number: per-flight fits, then flight 1's sag on flights 2 and 3."""
    from aerobat.quadrotor.identification.battery import fit_battery

    rows = []
    series = {}
    for name, index in FLIGHTS:
        series[(name, index)] = _series(name, index)
        fit = fit_battery([series[(name, index)]])
        assert fit is not None
        rows.append({"log": f"{name}:{index}", "rest_v": fit.rest_v, "sag_v": fit.sag_v,
                     "sag_fraction": fit.sag_v / fit.rest_v, "drain_v_per_min": fit.drain_v_per_s * 60.0,
                     "r_squared": fit.r_squared, "rms_v": fit.rms_v, "samples": fit.samples,
                     "full_load_thrust_factor": ((fit.rest_v - fit.sag_v) / fit.rest_v) ** 2})
    first = rows[0]["sag_v"]
    held = {f"diatone-roma-f5.bbl:{i}": _held_sag(series[("diatone-roma-f5.bbl", i)], first) for i in (2, 3)}
    forms = _forms(series[("diatone-roma-f5.bbl", 1)])
    return {"flights": rows, "roma_flight1_sag_on": held, "roma_flight1_load_forms_r_squared": forms}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if not LOGS.is_dir():
        print(f"results_battery.py: {LOGS} is absent (the shared flight logs are not here)", file=sys.stderr)
        return 2
    result = run()
    if args.json:
        print(json.dumps(result))
        return 0
    print("log                     rest [V]  sag [V]  sag/rest  drain [V/min]  R²     rms [V]  thrust at full load")
    for r in result["flights"]:
        print(f"{r['log']:22s}  {r['rest_v']:8.2f}  {r['sag_v']:7.2f}  {r['sag_fraction']:8.1%}  "
              f"{r['drain_v_per_min']:13.2f}  {r['r_squared']:.3f}  {r['rms_v']:7.2f}  "
              f"x {r['full_load_thrust_factor']:.2f}")
    print(f"the ROMA F5's flight-1 sag ({result['flights'][0]['sag_v']:.2f} V) on the other flights, rest and drain "
          f"refitted:")
    for name, h in result["roma_flight1_sag_on"].items():
        print(f"  {name}: R² {h['r_squared']:.3f}, rms {h['rms_v']:.2f} V")
    print("the ROMA F5's flight 1, R² with other loads: " + ", ".join(
        f"{name} {r2:.3f}" for name, r2 in result["roma_flight1_load_forms_r_squared"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
