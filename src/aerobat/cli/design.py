"""``aerobat design``: the nominal design of a maneuver — p^g, p⁰, residual, J, C, conditioning."""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from aerobat.cli.common import (
    HelpFormatter,
    add_maneuver_options,
    add_plant_options,
    console,
    maneuver_from_args,
    plant_choice_from_args,
)
from aerobat.errors import ConfigError, DesignFailed

__all__ = ["register"]


def _cmd_design(args: argparse.Namespace) -> int:
    from aerobat.experiments.designing import nominal_design
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = maneuver_from_args(args, config)
    if args.plant is None and (args.tune is not None or args.design_model == "firmware"):
        raise ConfigError(f"{'--tune' if args.tune is not None else '--design-model firmware'}: name the plant "
                          f"whose firmware flies the program (--plant betaflight or fc)")
    if args.plant is None:
        from aerobat.plants import PLANTS

        for name, spec in PLANTS.items():  # a settings file without its plant is refused, never ignored
            if spec.option is not None and getattr(args, spec.option.lstrip("-").replace("-", "_"), None) is not None:
                raise ConfigError(f"{spec.option} applies only with --plant {name} (no --plant given)")
    plant = plant_choice_from_args(args) if args.plant is not None else None
    if args.program is not None:  # refused before the design: the store (D1), an existing file without --force
        from pathlib import Path

        from aerobat.cli.common import refuse_overwrite

        refuse_overwrite(Path(args.program), store_path=None, force=args.force, option="--program")
    nominal = nominal_design(maneuver, config, plant=plant, design_model=args.design_model,
                             correction=args.correction)
    result = nominal.design
    if args.json:
        print(json.dumps({**result.to_json_dict(), "design_model": nominal.model.value,
                          "design_model_description": nominal.description,
                          "design_model_compute_s": nominal.compute_s,
                          "full_output_share": nominal.full_output_share}))
    else:
        _print_design(result, nominal.model_lines())
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
        f"{args.vehicle}{', for --plant ' + args.plant if args.plant else ''})"))
    try:
        save_program(program, path)
    except OSError as exc:
        raise OutputError(f"--program {path}: cannot write: {exc.strerror or exc}") from None
    print(f"program p⁰ written to {path}; fly it with `aerobat fly {path}`",
          file=sys.stderr if args.json else sys.stdout)


def _print_design(result: Any, model: list[str]) -> None:
    """The design's summary with the ``model`` lines under its first (status) line, then singular values, J and C."""
    out = console()
    first, *rest = result.summary().splitlines()
    for line in (first, *model, *rest):
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
    add_plant_options(p, default=None, feedback=False)
    p.set_defaults(func=_cmd_design)
