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
    if args.program is not None:  # refused before the design: the store (D1), an existing file without --force
        from pathlib import Path

        from aerobat.cli.common import refuse_overwrite

        refuse_overwrite(Path(args.program), store_path=None, force=args.force, option="--program")
    result = design(maneuver, NominalModel(config), correction=args.correction)
    if args.json:
        print(json.dumps(result.to_json_dict()))
    else:
        _print_design(result)
    if not result.converged:
        raise DesignFailed(result.message, result)
    if args.program is not None:
        _write_program(maneuver, result, args)
    return 0


def _write_program(maneuver: Any, result: Any, args: argparse.Namespace) -> None:
    import dataclasses
    import sys
    from pathlib import Path

    from aerobat import __version__
    from aerobat.cli.common import refuse_overwrite
    from aerobat.errors import OutputError
    from aerobat.quadrotor.program import save_program

    path = Path(args.program)
    refuse_overwrite(path, store_path=None, force=args.force, option="--program")  # never the default store (D1)
    program = dataclasses.replace(maneuver.program(result.p_nominal), provenance=(
        f"aerobat {__version__}: aerobat {' '.join(args.argv)} (the nominal design p⁰ of {maneuver.name} on "
        f"{args.vehicle})"))
    try:
        save_program(program, path)
    except OSError as exc:
        raise OutputError(f"--program {path}: cannot write: {exc.strerror or exc}") from None
    print(f"program p⁰ written to {path}; fly it with `aerobat fly {path}`",
          file=sys.stderr if args.json else sys.stdout)


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
    p.add_argument("--program", metavar="FILE.toml", default=None,
                   help="write the nominal program p⁰ to FILE, for `aerobat fly` (default: none)")
    p.add_argument("--force", action="store_true", help="replace --program if it exists")
    p.set_defaults(func=_cmd_design)
