"""Regenerate the design envelope of docs/results.md ("Design envelope") and its figures (seconds).

Runs ``aerobat study envelope --flips 1,2,3,4 --rates-deg-s 600:2000:8`` (2D roll flips on the
nominal model) into a temporary store, writes its figures and ``envelope.json`` to
docs/figures/envelope/, and prints the table: duration and apex above the start per design, "—"
where no design was found, "(c)" where the design converged only by continuation from its
neighbours in rate (:func:`aerobat.experiments.jobs.design_job`).

Run: .venv/bin/python scripts/results_envelope.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "envelope"


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "aerobat.cli", "study", "envelope", "--flips", "1,2,3,4",
                        "--rates-deg-s", "600:2000:8", "--db", f"{tmp}/envelope.sqlite", "--out", str(OUT)],
                       check=True, stdout=subprocess.DEVNULL)
    (OUT / ".aerobat-owner").unlink(missing_ok=True)  # the study's mark on its folder: not part of the docs
    rows = json.loads((OUT / "envelope.json").read_text())
    rates = sorted({r["max_rate_deg_s"] for r in rows})
    flips = sorted({r["flips"] for r in rows})
    found = sum(1 for r in rows if r["converged"])
    continued = [r for r in rows if r.get("continued_from_deg_s")]
    print(f"{found} of {len(rows)} designs converge ({len(continued)} by continuation).\n")
    print("| flips \\ max rate [°/s] | " + " | ".join(f"{r:g}" for r in rates) + " |")
    print("|---|" + "---|" * len(rates))
    for n in flips:
        cells = []
        for rate in rates:
            c = next(x for x in rows if x["flips"] == n and x["max_rate_deg_s"] == rate)
            cells.append("—" if not c["converged"] else f"{c['duration_s']:.2f} s, {c['apex_m']:.3g} m"
                         + (" (c)" if c.get("continued_from_deg_s") else ""))
        print(f"| {n} | " + " | ".join(cells) + " |")
    for c in continued:
        low, high = c["continued_from_deg_s"]
        print(f"\n{c['flips']} flips at {c['max_rate_deg_s']:g}°/s: converged from the mean p⁰ of the same flip at "
              f"{low:g} and {high:g}°/s")


if __name__ == "__main__":
    main()
