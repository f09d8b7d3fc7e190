"""Every number of docs/results.md's "Feedback" section (issue 15), from aerobat's own commands.

    .venv/bin/python scripts/results_feedback.py            # all of it (about an hour on 2 cores)
    .venv/bin/python scripts/results_feedback.py flip        # one part (names below, PARTS)

Each part runs an ``aerobat study`` with ``--json`` into a scratch store, prints the markdown
table quoted in docs/results.md and copies the study's figure to docs/figures/feedback/.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures" / "feedback"
AEROBAT = [sys.executable, "-m", "aerobat.cli"]
FLIP = ["flip", "--flips", "3", "--max-rate-deg-s", "1800", "--dims", "3"]


def run(args: list[str], scratch: Path) -> dict:
    command = [*AEROBAT, *args, "--db", str(scratch / "feedback.sqlite"), "--json"]
    print("$ aerobat " + " ".join(args), file=sys.stderr, flush=True)
    done = subprocess.run(command, capture_output=True, text=True, cwd=scratch, check=False)
    if done.returncode != 0:
        raise SystemExit(f"failed ({done.returncode}): {' '.join(command)}\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def feedback_table(report: dict, title: str) -> None:
    print(f"\n{title}\n")
    print("| scenario | scheme | last-10 mean [m] | worst seed [m] | mean angle errors, last 10 [°] "
          "| median trials to 0.12 m | failed runs | ms per trial |")
    print("|---|---|---:|---:|---|---:|---:|---:|")
    for r in report["rows"]:
        angles = " / ".join(f"{a:.2f}" for a in r["last10_angle_deg"]) or "—"
        print(f"| {r['scenario']} | {r['scheme']} | {r['last10_mean_m']:.3f} | {r['last10_worst_seed_m']:.3f} | "
              f"{angles} | {r['median_trials_to_tolerance']:g} | {r['failures']}/{r['runs']} | "
              f"{r['wall_ms_per_trial']:.1f} |")


def study_feedback(name: str, args: list[str], scratch: Path, title: str) -> None:
    out = scratch / name
    report = run(["study", "feedback", *args, "--out", str(out)], scratch)
    feedback_table(report, title)
    FIGURES.mkdir(parents=True, exist_ok=True)
    shutil.copy(out / "feedback.png", FIGURES / f"{name}.png")


def robustness(scratch: Path) -> None:
    print("\n1,000 sampled arena vehicles, 3D triple flip, 30 trials each:\n")
    print("| feedback | success (last-10 mean ≤ 0.12 m) | median trials to 0.12 m | failed jobs |")
    print("|---|---:|---:|---:|")
    for scheme in ("none", "tracking"):
        r = run(["study", "robustness", *FLIP, "--vehicles", "1000", "--trials", "30", "--seed", "1",
                 "--feedback", scheme, "--out", str(scratch / f"robustness-{scheme}")], scratch)
        print(f"| {scheme} | {100 * r['success_rate']:.1f} % | {r['median_trials_to_tolerance']:g} | "
              f"{len(r['failed_jobs'])} |")


PARTS = {
    "flip": lambda s: study_feedback("flip", [*FLIP, "--seeds", "20", "--trials", "30"], s,
                                     "3D triple flip at 1800 °/s, arena, 20 seeds × 30 trials (rule paper):"),
    "translation": lambda s: study_feedback(
        "translation", ["translation", "--to", "5,5", "--seeds", "7", "--trials", "30", "--scenarios", "default"], s,
        "(5, 5) translation, arena, seeds 0–6 × 30 trials (rule paper):"),
    "rotorpy": lambda s: study_feedback(
        "rotorpy", [*FLIP, "--plant", "rotorpy", "--seed", "1", "--seeds", "3", "--trials", "30",
                    "--scenarios", "default"], s,
        "3D triple flip at 1800 °/s, RotorPy, seeds 1–3 × 30 trials, rule paper:"),
    "rotorpy-broyden": lambda s: study_feedback(
        "rotorpy-broyden", [*FLIP, "--plant", "rotorpy", "--seed", "1", "--seeds", "3", "--trials", "30",
                            "--scenarios", "default", "--rule", "broyden"], s,
        "3D triple flip at 1800 °/s, RotorPy, seeds 1–3 × 30 trials, rule broyden:"),
    "betaflight": lambda s: study_feedback(
        "betaflight", ["flip", "--flips", "3", "--max-rate-deg-s", "1800", "--dims", "3", "--vehicle", "fpv5",
                       "--plant", "betaflight", "--seed", "1", "--seeds", "3", "--trials", "30",
                       "--scenarios", "default", "--schemes", "none,tracking"], s,
        "3D triple flip at 1800 °/s, Betaflight 4.6 (fpv5), seeds 1–3 × 30 trials, rule paper:"),
    "robustness": robustness,
}


def main(argv: list[str]) -> int:
    parts = argv or list(PARTS)
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        raise SystemExit(f"unknown part(s) {', '.join(unknown)}; use {', '.join(PARTS)}")
    with tempfile.TemporaryDirectory() as tmp:
        for part in parts:
            PARTS[part](Path(tmp))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
