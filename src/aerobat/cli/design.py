"""``aerobat design``: the nominal design of a maneuver — p^g, p⁰, residual, J, C, conditioning."""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from aerobat.cli.common import HelpFormatter, add_maneuver_options, console, maneuver_from_args
from aerobat.errors import DesignFailed

__all__ = ["register"]


def _cmd_design(args: argparse.Namespace) -> int:
    from aerobat.core.design import design
    from aerobat.quadrotor.simulate import NominalModel
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = maneuver_from_args(args, config)
    result = design(maneuver, NominalModel(config), correction=args.correction)
    if args.json:
        print(json.dumps(result.to_json_dict()))
    else:
        _print_design(result)
    if not result.converged:
        raise DesignFailed(result.message, result)
    return 0


def _print_design(result: Any) -> None:
    out = console()
    for line in result.summary().splitlines():
        out.print(line)
    m = result.maneuver
    out.print("singular values: " + np.array2string(result.singular_values, precision=4))
    with np.printoptions(precision=4, suppress=False, linewidth=100):
        out.print(f"J (rows: {', '.join(e.name for e in m.errors)}):\n{result.jacobian}")
        out.print(f"C:\n{result.correction}")


def register(sub: Any) -> None:
    p = sub.add_parser("design", help="nominal design: p⁰, J, C",
                       formatter_class=HelpFormatter)
    add_maneuver_options(p)
    p.set_defaults(func=_cmd_design)
