"""``aerobat setup [--check]``: build the Betaflight SITL, compile the kernels, say what is missing."""

from __future__ import annotations

import argparse
import json
from typing import Any

from aerobat.cli.common import HelpFormatter, console
from aerobat.errors import ConfigError

__all__ = ["register"]


def _report_rows(report: Any) -> list[dict[str, Any]]:
    return [{"name": p.name, "kind": p.kind.value, "present": p.present, "detail": p.detail, "enables": p.enables,
             "how_to_get": p.how_to_get} for p in report.pieces]


def _print_report(report: Any) -> None:
    from aerobat.experiments.installation import PieceKind

    say = console().print
    for p in report.pieces:
        mark = "ok     " if p.present else ("MISSING" if p.kind is PieceKind.REQUIRED else "missing")
        say(f"{mark}  {p.name}: {p.detail}", markup=False, highlight=False)
        if not p.present:
            say(f"         needed for: {p.enables}", markup=False, highlight=False)
            say(f"         to get it: {p.how_to_get}", markup=False, highlight=False)
    missing = report.missing
    optional = [p for p in missing if p.kind is PieceKind.OPTIONAL]
    if not report.ok:
        say("aerobat cannot run: a required piece is missing (above)", markup=False)
    elif optional:
        say(f"aerobat works; {len(optional)} optional piece{'s' if len(optional) != 1 else ''} missing, "
            "each with what it would enable (above)", markup=False)
    else:
        say("everything is present", markup=False)


def _cmd_setup(args: argparse.Namespace) -> int:
    from aerobat.experiments.installation import check_installation, set_up

    if args.check:
        report = check_installation()
        if args.json:
            print(json.dumps({"pieces": _report_rows(report), "ok": report.ok}))
        else:
            _print_report(report)
        return 0 if report.ok else 1
    progress = (lambda line: None) if args.json else (lambda line: console().print(line, markup=False))
    groups = tuple(g.strip() for g in args.kernels.split(",")) if args.kernels else None
    if groups is not None:
        from aerobat.experiments.warmup import PARTS

        unknown = sorted(set(groups) - set(PARTS))
        if unknown:
            raise ConfigError(f"--kernels {args.kernels}: unknown group(s) {', '.join(unknown)}; allowed: "
                              f"{', '.join(PARTS)}")
    result = set_up(betaflight=not args.no_betaflight, kernels=not args.no_kernels, progress=progress,
                    kernel_groups=groups)
    if args.json:
        print(json.dumps({"steps": [{"step": s, "outcome": o.value, "message": m} for s, o, m in result.steps],
                          "pieces": _report_rows(result.report), "ok": result.report.ok and not result.failed}))
    else:
        for step, outcome, message in result.steps:
            console().print(f"{step}: {outcome.value}: {message}", markup=False, highlight=False)
        _print_report(result.report)
    return 1 if result.failed or not result.report.ok else 0


def register(sub: Any) -> None:
    p = sub.add_parser("setup", formatter_class=HelpFormatter,
                       help="build the Betaflight SITL and compile the kernels; --check says what is missing",
                       description="Set up what pip does not: the Betaflight 4.6 SITL with aerobat's lockstep "
                                   "patch (into ~/.cache/aerobat, needs a C compiler), and the compiled kernels. "
                                   "Then list every piece, what it enables, and how to get a missing one. "
                                   "Exit 1 when a step was tried and failed, or a required piece is missing.")
    p.add_argument("--check", action="store_true",
                   help="only look: install, build and compile nothing (default: set up, then look)")
    p.add_argument("--no-betaflight", action="store_true", help="do not build the Betaflight SITL (default: build it)")
    p.add_argument("--no-kernels", action="store_true", help="do not compile the kernels (default: compile them)")
    p.add_argument("--kernels", metavar="GROUPS", default=None,
                   help="compile only these kernel groups, comma-separated: playback, arena, plants, firmware "
                        "(make demo: playback,arena) (default: all)")
    p.add_argument("--json", action="store_true", help="print one JSON object (default: a list)")
    p.set_defaults(func=_cmd_setup)
