"""The ROMA F5 end to end (issue 24): identified from its own log, learned on its own tune.

Run (needs ../shared/data and the Betaflight SITL; about 1.5 min a seed on two cores):

    .venv/bin/python scripts/results_roma.py                 # seeds 0 1 2 3, designed on the firmware
    .venv/bin/python scripts/results_roma.py --design-model paper
    .venv/bin/python scripts/results_roma.py --seeds 1 --json
    .venv/bin/python scripts/results_roma.py --no-battery    # without the pack's sag under load (issue 42)
    .venv/bin/python scripts/results_roma.py --vibration     # flying the vibration identify found (issue 42)

1. ``aerobat identify --log diatone-roma-f5.bbl:1`` (0.55 kg and motors at ±0.08 m given, as the
   log does not know them) writes the design model and the Betaflight plant's airframe;
2. ``aerobat learn flip --flips 3 --dims 3 --max-rate-deg-s 600`` designs the 3D triple flip on
   the identified vehicle (``--design-model``: the firmware model by default, the tune's own
   Betaflight around the identified airframe; ``paper``: the paper's model) and learns it open loop
   through Betaflight running the tune in the same log's header (its rates top out at 667 °/s, so
   the coast rate is 600 °/s, not 1800).

It prints, per seed, the first attempt's miss, the last-10 mean, and the trials flown, measured
and lost, read back from the store; docs/plants.md quotes them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT.parent / "shared" / "data" / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
IDENTIFY = ["--vehicle", "fpv5", "--mass-kg", "0.55", "--motor-x-m", "0.08", "--motor-y-m", "0.08"]
FLIP = ["flip", "--flips", "3", "--dims", "3", "--max-rate-deg-s", "600"]


def run_aerobat(argv: list[str], *, may_fail: bool = False) -> str | None:
    """Run one aerobat command; its failure ends the script, or with ``may_fail`` is returned (its last line)."""
    from aerobat.cli.app import main

    with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.redirect_stderr(io.StringIO()) as err:
        code = main(argv)
    if code == 0:
        return None
    said = (out.getvalue() + err.getvalue()).strip()
    if may_fail:
        return next((line for line in reversed(said.splitlines()) if "crashed" in line or "failed" in line),
                    said.splitlines()[-1] if said else f"exited {code}")
    raise SystemExit(f"aerobat {' '.join(argv)} exited {code}:\n{said[-2000:]}")


def run(seeds: list[int], work: Path, trials: int = 30, design_model: str = "firmware",
        battery: bool = True, vibration: bool = False) -> dict[str, Any]:
    """Identify once, then learn the triple flip once per seed; every number read from the store.

    ``battery``: the identified pack's sag under load stays in the airframe (plant and firmware model);
    False drops it (thrust as identified at any load, the chain before issue 42's battery model).
    ``vibration``: the vibration ``identify`` found moves into the airframe, as its comment says (the gyro
    carries the rotors' lines; the thrust coefficient the rotors' speed); False leaves the file as written.
    """
    import tomllib

    import tomli_w

    from aerobat.fileio import write_output
    from aerobat.store import Store

    vehicle, airframe, db = work / "roma.toml", work / "roma_bf.toml", work / "roma.sqlite"
    started = time.perf_counter()
    run_aerobat(["identify", "--log", f"{LOG}:1", *IDENTIFY, "--output", str(vehicle), "--airframe", str(airframe),
              "--figure", str(work / "roma.png")])
    identify_s = time.perf_counter() - started
    text = airframe.read_text()
    table = tomllib.loads(text)
    if not battery:
        table["airframe"].pop("battery_rest_v", None)
        table["airframe"]["battery_sag_v"] = 0.0
    if vibration:  # the commented lines identify wrote, moved under [airframe] as a user would
        lines = [line[4:] for line in text.splitlines() if line.startswith("#   ")]
        if not lines:
            raise SystemExit(f"{airframe}: identify wrote no vibration (the log has no unfiltered gyro)")
        table["airframe"].update(tomllib.loads("\n".join(lines)))
    if not battery or vibration:
        write_output(airframe, tomli_w.dumps(table))
    pack = {"rest_v": table["airframe"].get("battery_rest_v"), "sag_v": table["airframe"].get("battery_sag_v"),
            "reference_v": table["airframe"].get("battery_reference_v")}
    rows = []
    for seed in seeds:
        started = time.perf_counter()
        # a session a crash ends is a result: its trials are read back and the crash is reported
        ended = run_aerobat(["learn", *FLIP, "--vehicle", str(vehicle), "--plant", "betaflight", "--betaflight",
                          str(airframe), "--tune", str(LOG), "--feedback", "none", "--trials", str(trials), "--seed",
                          str(seed), "--design-model", design_model,
                          "--db", str(db), "--out", str(work / f"seed-{seed}")], may_fail=True)
        with Store(db, create=False) as store:
            sid = store.list_sessions()[-1].id
            records = store.iterations(sid)
            mask = np.array(store.maneuver(store.session(sid).maneuver_id).position_mask, dtype=bool)
        errors = [float(np.linalg.norm(r.error[mask])) for r in records if r.status == "ok"]
        rows.append({"seed": seed, "trials": len(records), "measured": len(errors),
                     "lost": len(records) - len(errors), "first_m": errors[0] if errors else None,
                     "last10_mean_m": float(np.mean(errors[-10:])) if errors else None,
                     "best_m": min(errors) if errors else None, "ended": ended,
                     "wall_s": round(time.perf_counter() - started, 1)})
    return {"identify_s": round(identify_s, 1), "design_model": design_model, "battery": pack, "seeds": rows}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3], help="plant seeds, one session each")
    parser.add_argument("--design-model", choices=("paper", "firmware"), default="firmware",
                        help="the model the triple flip is designed on")
    parser.add_argument("--trials", type=int, default=30, help="trials per session")
    parser.add_argument("--no-battery", action="store_true",
                        help="drop the identified pack's sag under load from the airframe (thrust as identified)")
    parser.add_argument("--vibration", action="store_true",
                        help="fly the vibration identify found (the rotors' lines in the gyro, their speed)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if not LOG.is_file():
        print(f"results_roma.py: {LOG} is absent (the shared flight logs are not here)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="aerobat-roma-") as work:
        result = run(args.seeds, Path(work), trials=args.trials, design_model=args.design_model,
                     battery=not args.no_battery, vibration=args.vibration)
    ended = any(r["ended"] for r in result["seeds"])  # a session a crash ended is reported, and the exit says so
    if args.json:
        print(json.dumps(result))
        return 1 if ended else 0
    print(f"identified from {LOG.name}:1 in {result['identify_s']:.1f} s; designed on the {args.design_model} model")
    pack = result["battery"]
    print("battery: " + (f"rest {pack['rest_v']:.2f} V, sag {pack['sag_v']:.2f} V at full load, reference "
                         f"{pack['reference_v']:.2f} V" if pack["rest_v"] is not None
                         else "off (thrust as identified)"))
    print("seed  trials  measured  lost  first [m]  last-10 mean [m]  best [m]  wall [s]")
    def metres(value: float | None, width: int) -> str:
        return f"{value:{width}.3f}" if value is not None else f"{'-':>{width}s}"

    for r in result["seeds"]:
        print(f"{r['seed']:4d}  {r['trials']:6d}  {r['measured']:8d}  {r['lost']:4d}  {metres(r['first_m'], 9)}  "
              f"{metres(r['last10_mean_m'], 16)}  {metres(r['best_m'], 8)}  {r['wall_s']:8.1f}"
              + (f"  ended: {r['ended']}" if r["ended"] else ""))
    return 1 if ended else 0


if __name__ == "__main__":
    raise SystemExit(main())
