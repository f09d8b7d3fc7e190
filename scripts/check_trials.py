"""Digest of raw trials on each plant, failures included, to show a refactoring of the plants changes no trial.

Flies, per plant, the designed 3D triple flip a few times and a 1 s thrust cut (a crash) three times,
from seed 3; the arena with 20 % of its triggers and 30 % of its upload packets lost, so that lost
triggers and retries are flown too. Prints, per trial, its status, message, info (wall-clock fields
left out) and a SHA-256 over its final, start and measured states and its signals.

    python scripts/check_trials.py > before.json              # on the old code
    python scripts/check_trials.py > after.json               # on the new code
    python scripts/check_trials.py --compare before.json after.json

Run both sides with their kernels compiled the same way (``aerobat setup``): a kernel numba compiled
inside the run and one loaded from the cache may differ in the last bits.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
from typing import Any

import numpy as np

_VOLATILE = {"wall_s", "real_time_factor", "firmware_cpu_s", "wall_per_firmware_cpu", "firmware_spin_s",
             "driver_spin_s", "compiled_calls", "driver_sleeping_share", "driver_spin_switches", "driver_spin_probes",
             "firmware"}


def _clean(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in sorted(value.items()) if k not in _VOLATILE}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, float):
        return repr(value)
    return value


def _digest(trial: Any) -> dict[str, Any]:
    h = hashlib.sha256()
    for array in (trial.final_state, trial.times_s, trial.states, trial.start_state):
        h.update(np.ascontiguousarray(array, dtype=float).tobytes())
    if trial.signals is not None:
        h.update(np.ascontiguousarray(trial.signals.values, dtype=float).tobytes())
    return {"status": trial.status.value, "message": trial.message, "info": _clean(trial.info),
            "sha256": h.hexdigest()[:16]}


def fly(plants: list[str], seed: int) -> dict[str, list[dict[str, Any]]]:
    """The digests of every trial flown on each of ``plants``."""
    from aerobat import MultiFlip, NominalModel, design, hummingbird, preset
    from aerobat.plants import PlantChoice
    from aerobat.quadrotor.program import Program, Switch

    out = {}
    for name in plants:
        # "betaflight-udp": the firmware over loopback sockets instead of shared memory; "nominal-lagged":
        # a vehicle with rate-loop latency (the delayed continuous playback)
        kind = name.split("-")[0]
        config = preset("fpv5") if kind in ("betaflight",) else hummingbird()
        if name == "nominal-lagged":
            lagged = dataclasses.replace(config.effects, rate_latency_s=(0.004, 0.004, 0.006))
            config = dataclasses.replace(config, effects=lagged)
        flip = MultiFlip(vehicle=config.vehicle, flips=3, dims=3)
        program = flip.program(design(flip, NominalModel(config)).p_nominal)
        hover = config.vehicle.gravity_m_s2
        cut = Program(switches=(Switch(time_s=0.0, channel="collective", value=0.5),
                                Switch(time_s=0.9, channel="collective", value=hover)),
                      duration_s=1.0, hover_collective_m_s2=hover)
        settings = None
        if kind == "arena":
            from aerobat.plants import ArenaParams

            settings = ArenaParams().replace(links__command_drop_probability=0.2, links__upload_drop_probability=0.3)
        if name == "betaflight-udp":
            from aerobat.plants.fpv.params import BetaflightParams

            settings = BetaflightParams().replace(firmware__exchange="udp")
        plant = PlantChoice(kind, settings, seed=seed).build(config)
        good = 8 if kind in ("arena", "nominal") else 2
        trials = [plant.fly(program) for _ in range(good)] + [plant.fly(cut) for _ in range(3)] + [plant.fly(program)]
        out[name] = [_digest(t) for t in trials]
        print(name, [t.status.value for t in trials], file=sys.stderr)
    return out


def compare(before: dict[str, Any], after: dict[str, Any]) -> int:
    """Print each trial that differs; the number of them."""
    differ = 0
    for kind in sorted(set(before) | set(after)):
        a, b = before.get(kind, []), after.get(kind, [])
        if len(a) != len(b):
            print(f"{kind}: {len(a)} trials before, {len(b)} after")
            differ += 1
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            if x != y:
                differ += 1
                print(f"{kind} trial {i}: {x['status']} {x['sha256']} -> {y['status']} {y['sha256']}"
                      + ("" if x["info"] == y["info"] else " (info differs)"))
    print(f"{differ} trials differ")
    return differ


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", default="arena,nominal,nominal-lagged,rotorpy,betaflight,betaflight-udp",
                        help="comma list of plants")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), help="compare two digests")
    args = parser.parse_args()
    if args.compare:
        with open(args.compare[0]) as f, open(args.compare[1]) as g:
            return 1 if compare(json.load(f), json.load(g)) else 0
    print(json.dumps(fly(args.plants.split(","), args.seed), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
