"""``aerobat tune FILE``: what a real quad's Betaflight tune becomes on the SITL, before anything flies.

The same reading, translation and checks as ``--tune FILE`` on a command that flies (docs/plants.md,
"Your tune in the loop"), without starting the firmware: every setting applied, translated, refused
or pinned, the commands the firmware's CLI would get and the tune's full-stick rates.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from aerobat.cli.common import HelpFormatter, bounded_int, plural
from aerobat.cli.tune_options import read_tune

__all__ = ["register"]


def _cmd_tune(args: argparse.Namespace) -> int:
    report, rates, rates_type = read_tune(args.file, args.log_index, "--log-index")
    if args.json:
        print(json.dumps({**report.to_table(), "rates_type": rates_type,
                          "full_stick_rates_deg_s": {axis: round(rate, 2) for axis, rate in rates.items()}}))
        return 0
    shown = ", ".join(f"{axis} {rate:.0f}" for axis, rate in rates.items())
    print(f"{report.text()}\n  full-stick rates [deg/s] ({rates_type}): {shown}\n  "
          f"{plural(len(report.commands), 'CLI command')} for the firmware, then aerobat's pinned ones")
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("tune", help="what a real quad's Betaflight tune (a CLI diff or dump, or a blackbox log's "
                                    "header) becomes on the SITL: applied, translated, refused, pinned; nothing flies",
                       formatter_class=HelpFormatter)
    p.add_argument("file", metavar="FILE[:N]", help="a Betaflight CLI diff or dump, or a blackbox log .bbl, .bfl or "
                                                    ".txt, FILE:N its log N (default 1) (required)")
    p.add_argument("--log-index", type=bounded_int(1, 10**6), default=None, metavar="N",
                   help=argparse.SUPPRESS)  # before FILE:N; kept so that older command lines still run
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_tune)
