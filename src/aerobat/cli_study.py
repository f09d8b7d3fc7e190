"""``aerobat study``: Monte Carlo robustness and design-envelope maps, on a local pool or Dask."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .cli import EXIT_OK, CommandFailed, _console

__all__ = ["register"]


def _executor(args: argparse.Namespace):
    from .execution import make_executor

    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise ValueError(f"--workers {args.workers}: allowed 1 … 1024")
    return make_executor(scheduler=args.scheduler, workers=args.workers)


def _run_jobs(args: argparse.Namespace, kind: str, spec: dict[str, Any], jobs, on_result) -> tuple[int, int, int]:
    """Run the jobs of a study not yet finished in the store; returns (study id, ran, skipped)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from .store import Store

    store = Store(args.db)
    try:
        study_id = store.resolve_study(args.resume) if args.resume else store.create_study(kind, spec)
        done = store.finished_study_jobs(study_id)
        todo = [job for job in jobs if job.key not in done]
        console = _console(False)
        executor = _executor(args)
        try:
            with Progress(TextColumn(f"study {study_id} ({kind})"), BarColumn(), MofNCompleteColumn(),
                          TimeElapsedColumn(), console=console, transient=True) as progress:
                task = progress.add_task(kind, total=len(jobs), completed=len(jobs) - len(todo))
                for job, result in executor.run(todo):
                    on_result(store, study_id, job, result)
                    progress.advance(task)
        finally:
            executor.close()
        return study_id, len(todo), len(jobs) - len(todo)
    finally:
        store.close()


# ----------------------------------------------------------------- robustness


def _cmd_robustness(args: argparse.Namespace) -> int:
    from .design import design
    from .simulate import NominalModel
    from .studies import RobustnessRanges, load_ranges, robustness_jobs, summarize_robustness
    from .vehicle import vehicle_from_name_or_file

    if not 1 <= args.vehicles <= 100000:
        raise ValueError(f"--vehicles {args.vehicles}: allowed 1 … 100000")
    if not 1 <= args.iterations <= 1000:
        raise ValueError(f"--iterations {args.iterations}: allowed 1 … 1000")
    if not (math.isfinite(args.tolerance_m) and args.tolerance_m > 0):
        raise ValueError(f"--tolerance-m {args.tolerance_m}: must be > 0")
    from .cli import _maneuver_from_args

    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = _maneuver_from_args(args, config)
    nominal = design(maneuver, NominalModel(config), correction=args.correction)
    if not nominal.converged:
        raise CommandFailed(f"design failed: {nominal.message}")
    ranges = load_ranges(args.ranges) if args.ranges else RobustnessRanges()
    jobs = robustness_jobs(maneuver, nominal, vehicles=args.vehicles, iterations=args.iterations, seed=args.seed,
                           ranges=ranges, rule=args.rule, tolerance_m=args.tolerance_m)
    spec = {"maneuver": maneuver.spec(), "vehicles": args.vehicles, "iterations": args.iterations,
            "seed": args.seed, "rule": args.rule, "tolerance_m": args.tolerance_m,
            "ranges": {k: list(v) if isinstance(v, tuple) else v for k, v in ranges.__dict__.items()}}

    def record(store, study_id, job, result) -> None:
        store.record_study_job(study_id, job.key, job.spec, result)

    study_id, ran, skipped = _run_jobs(args, "robustness", spec, jobs, record)
    from .store import Store

    with Store(args.db) as store:
        results = [r for _, r in sorted(store.study_results(study_id).items())]
    summary = summarize_robustness(results)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _robustness_figures(results, summary, out, args.tolerance_m)
    report = {
        "study": study_id, "vehicles": summary.vehicles, "completed": summary.completed,
        "success_rate": summary.success_rate, "median_trials_to_tolerance": summary.median_trials_to_tolerance,
        "median_final_error_m": float(np.nanmedian(summary.final_errors_m)) if summary.final_errors_m else None,
        "predictors": summary.predictors, "ran": ran, "skipped": skipped,
    }
    (out / "robustness.json").write_text(json.dumps(report, indent=1))
    if args.json:
        print(json.dumps(report))
    else:
        console = _console(False)
        console.print(f"study {study_id}: {summary.completed}/{summary.vehicles} vehicles learned "
                      f"({ran} run now, {skipped} already done)")
        console.print(f"success (mean of the last 10 position errors ≤ {args.tolerance_m:g} m): "
                      f"{100 * summary.success_rate:.1f} %")
        console.print(f"median trials to {args.tolerance_m:g} m: {summary.median_trials_to_tolerance:g}")
        if summary.predictors:
            console.print("properties most correlated with failure: " + ", ".join(
                f"{name} ({corr:+.2f})" for name, corr in summary.predictors[:4]))
        console.print(f"figures and robustness.json in {out}/")
    return EXIT_OK


def _robustness_figures(results, summary, out: Path, tolerance_m: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .studies import SAMPLED_PROPERTIES

    ttt = [t for t in summary.trials_to_tolerance if t is not None]
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    if ttt:
        ax.hist(ttt, bins=[float(b) for b in np.arange(0.5, max(ttt) + 1.5)], color="C0")
    never = sum(1 for t in summary.trials_to_tolerance if t is None)
    ax.set_xlabel(f"trials until the position error first falls below {tolerance_m:g} m")
    ax.set_ylabel("vehicles")
    ax.set_title(f"{len(ttt)} reached the tolerance, {never} never did")
    fig.savefig(out / "trials_to_tolerance.png", dpi=120)
    plt.close(fig)
    done = [r for r in results if r.get("status") != "error" and r.get("properties")]
    if not done:
        return
    success = np.array([bool(r.get("success")) for r in done])
    cols = 4
    rows = math.ceil(len(SAMPLED_PROPERTIES) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), constrained_layout=True)
    for ax, name in zip(np.ravel(axes), SAMPLED_PROPERTIES, strict=False):
        values = np.array([r["properties"][name] for r in done])
        edges = np.unique(np.quantile(values, np.linspace(0, 1, 6)))
        if len(edges) < 2:
            continue
        which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
        rate = [success[which == k].mean() if np.any(which == k) else np.nan for k in range(len(edges) - 1)]
        centers = 0.5 * (edges[1:] + edges[:-1])
        ax.plot(centers, np.array(rate) * 100, "o-")
        ax.set_title(name, fontsize=8)
        ax.set_ylim(-5, 105)
        ax.set_ylabel("success [%]", fontsize=8)
    for ax in np.ravel(axes)[len(SAMPLED_PROPERTIES):]:
        ax.axis("off")
    fig.savefig(out / "success_vs_property.png", dpi=120)
    plt.close(fig)


# ------------------------------------------------------------------ envelope


def _parse_list(text: str, option: str, cast) -> list:
    try:
        if ":" in text:
            a, b, n = text.split(":")
            values = list(np.linspace(float(a), float(b), int(n))) if cast is float else list(
                range(int(a), int(b) + 1, max(1, int(n))))
        else:
            values = [cast(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"{option} {text!r}: expected a comma list or A:B:N") from None
    if not values or len(values) > 500:
        raise ValueError(f"{option} {text!r}: expected 1 … 500 values")
    return values


def _cmd_envelope(args: argparse.Namespace) -> int:
    from .maneuvers import MultiFlip
    from .studies import envelope_jobs
    from .vehicle import vehicle_from_name_or_file

    flips = _parse_list(args.flips, "--flips", int)
    rates = _parse_list(args.rates_deg_s, "--rates-deg-s", float)
    config = vehicle_from_name_or_file(args.vehicle)
    base = MultiFlip(vehicle=config.vehicle, dims=args.dims, axis=args.axis).spec()
    jobs = envelope_jobs(base, flips, rates)
    spec = {"base": base, "flips": flips, "rates_deg_s": rates}

    def record(store, study_id, job, result) -> None:
        store.record_study_job(study_id, job.key, job.spec, result)

    study_id, ran, skipped = _run_jobs(args, "envelope", spec, jobs, record)
    from .store import Store

    with Store(args.db) as store:
        results = store.study_results(study_id)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    grid = {q: np.full((len(flips), len(rates)), np.nan) for q in ("duration_s", "apex_m", "condition_number")}
    feasible = np.zeros((len(flips), len(rates)))
    rows = []
    for i, n in enumerate(flips):
        for j, rate in enumerate(rates):
            r = results.get(f"flips-{n}-rate-{rate:g}", {})
            feasible[i, j] = 1.0 if r.get("converged") else 0.0
            for q in grid:
                value = r.get(q)
                grid[q][i, j] = value if isinstance(value, float) else np.nan
            rows.append({"flips": n, "max_rate_deg_s": rate, **{k: r.get(k) for k in
                         ("converged", "status", "duration_s", "apex_m", "lowest_m", "condition_number")}})
    (out / "envelope.json").write_text(json.dumps(rows, indent=1))
    _envelope_figures(out, flips, rates, feasible, grid)
    console = _console(False)
    console.print(f"study {study_id}: {int(feasible.sum())}/{feasible.size} designs feasible "
                  f"({ran} run now, {skipped} already done); figures and envelope.json in {out}/")
    return EXIT_OK


def _envelope_figures(out: Path, flips, rates, feasible, grid) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = {"feasible": "design converged (1) or not (0)", "duration_s": "hover-to-hover duration [s]",
              "apex_m": "apex height above the start [m]", "condition_number": "condition number of J (log10)"}
    for name, values in (("feasible", feasible), *grid.items()):
        data = np.log10(values) if name == "condition_number" else values
        fig, ax = plt.subplots(figsize=(6, 3.5), constrained_layout=True)
        im = ax.imshow(data, origin="lower", aspect="auto", cmap="viridis",
                       extent=(rates[0], rates[-1], flips[0] - 0.5, flips[-1] + 0.5))
        fig.colorbar(im, ax=ax)
        ax.set_xlabel("max rate [deg/s]")
        ax.set_ylabel("flips")
        ax.set_title(titles[name])
        fig.savefig(out / f"envelope_{name}.png", dpi=120)
        plt.close(fig)


# ------------------------------------------------------------------ rules


DEFAULT_METHODS = "paper,tsvd,damped,kalman,broyden,tsvd+isc,cma,bayesopt"


def _cmd_rules(args: argparse.Namespace) -> int:
    import csv

    from rich.table import Table

    from .cli import _maneuver_from_args
    from .design import design
    from .simulate import NominalModel
    from .studies import rules_study_jobs, summarize_rules
    from .vehicle import vehicle_from_name_or_file

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    from .rules import RULE_NAMES

    known = set(RULE_NAMES) | {f"{r}+isc" for r in RULE_NAMES} | {"cma", "bayesopt"}
    bad = [m for m in methods if m not in known]
    if bad or not methods:
        raise ValueError(f"--methods: unknown {', '.join(bad) or '(none given)'}; allowed: {', '.join(sorted(known))}")
    if not 1 <= args.seeds <= 1000 or not 2 <= args.trials <= 1000:
        raise ValueError("--seeds must be 1 … 1000 and --trials 2 … 1000")
    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = _maneuver_from_args(args, config)
    nominal = design(maneuver, NominalModel(config), correction=args.correction)
    if not nominal.converged:
        raise CommandFailed(f"design failed: {nominal.message}")
    arena = None
    if args.arena:
        from .config import dataclass_to_table
        from .plants.arena import load_arena

        arena = dataclass_to_table(load_arena(args.arena))
    if args.plant == "rotorpy":
        from .plants.rotorpy import RotorPyPlant

        RotorPyPlant(config, seed=0)  # fails now, with the install hint, if RotorPy is missing
    jobs = rules_study_jobs(maneuver, nominal, methods=methods, seeds=args.seeds, trials=args.trials,
                            seed=args.seed, arena=arena, tolerance_m=args.tolerance_m, plant=args.plant)
    spec = {"maneuver": maneuver.spec(), "methods": methods, "seeds": args.seeds, "trials": args.trials,
            "seed": args.seed, "tolerance_m": args.tolerance_m, "arena": arena, "plant": args.plant}

    def record(store, study_id, job, result) -> None:
        store.record_study_job(study_id, job.key, job.spec, result)

    study_id, ran, skipped = _run_jobs(args, "rules", spec, jobs, record)
    from .store import Store

    with Store(args.db) as store:
        results = [r for _, r in sorted(store.study_results(study_id).items()) if "method" in r]
    rows = summarize_rules(results, args.trials)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with (out / "rules.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else ["method"])
        writer.writeheader()
        writer.writerows(rows)
    _rules_figure(results, methods, args.trials, args.tolerance_m, out / "rules.png")
    if args.json:
        print(json.dumps({"study": study_id, "methods": rows}))
    else:
        table = Table(title=f"study {study_id}: {maneuver.name}, {args.seeds} seeds × {args.trials} trials")
        for col in ("method", f"median trials to {args.tolerance_m:g} m", "reached", "share below after",
                    "last-10 mean [m]", "failures", "wall [s/run]"):
            table.add_column(col, justify="right" if col != "method" else "left")
        for r in rows:
            table.add_row(r["method"], f"{r['median_trials_to_tolerance']:g}", f"{r['reached']}/{r['runs']}",
                          f"{100 * r['share_below_after']:.0f} %", f"{r['last10_mean_m']:.3f}",
                          str(r["failures"]), f"{r['wall_s']:.1f}")
        console = _console(False)
        console.print(table)
        console.print(f"({ran} runs now, {skipped} already done); rules.csv and rules.png in {out}/")
    return EXIT_OK


def _rules_figure(results, methods, trials: int, tolerance_m: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    x = np.arange(1, trials + 1)
    for k, method in enumerate(methods):
        curves = [r["position_errors_m"] for r in results if r["method"] == method]
        if not curves:
            continue
        data = np.full((len(curves), trials), np.nan)
        for i, c in enumerate(curves):
            data[i, : min(trials, len(c))] = c[:trials]
        med = np.nanmedian(data, axis=0)
        q1, q3 = np.nanpercentile(data, 25, axis=0), np.nanpercentile(data, 75, axis=0)
        ax.plot(x, med, color=f"C{k}", label=method)
        ax.fill_between(x, q1, q3, color=f"C{k}", alpha=0.15)
    ax.axhline(tolerance_m, color="k", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_xlabel("trial")
    ax.set_ylabel("position error [m] (median, quartiles)")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ------------------------------------------------------------------ parser


def register(sub) -> None:
    from .cli import _add_flip_options

    study = sub.add_parser("study", help="Monte Carlo robustness and design-envelope studies")
    ssub = study.add_subparsers(dest="study", required=True, parser_class=type(study))

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--db", default=None, help="experiment store (default ./aerobat.sqlite)")
        p.add_argument("--scheduler", default=None,
                       help="Dask scheduler address tcp://HOST:PORT (default: $DASK_SCHEDULER_ADDRESS, else local)")
        p.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
        p.add_argument("--resume", default=None, metavar="STUDY", help="continue a study: run only unfinished jobs")
        p.add_argument("--out", default="out/study", help="directory for figures and the report")

    rob = ssub.add_parser("robustness", help="learn one maneuver on K sampled vehicles")
    _add_flip_options(rob)
    rob.add_argument("--vehicles", type=int, default=100, help="number of sampled vehicles K")
    rob.add_argument("--iterations", type=int, default=30)
    rob.add_argument("--seed", type=int, default=0)
    rob.add_argument("--rule", default="paper", help="update rule (see docs/method.md)")
    rob.add_argument("--tolerance-m", type=float, default=0.12)
    rob.add_argument("--ranges", metavar="FILE.toml", help="sampling ranges ([ranges] table)")
    common(rob)
    rob.set_defaults(func=_cmd_robustness)

    rules = ssub.add_parser("rules", help="every update rule and two model-free baselines, side by side")
    _add_flip_options(rules)
    rules.add_argument("--methods", default=DEFAULT_METHODS, help=f"comma list (default {DEFAULT_METHODS})")
    rules.add_argument("--seeds", type=int, default=20)
    rules.add_argument("--trials", type=int, default=30)
    rules.add_argument("--seed", type=int, default=1, help="first arena seed")
    rules.add_argument("--tolerance-m", type=float, default=0.12)
    rules.add_argument("--arena", metavar="FILE.toml", help="arena configuration")
    rules.add_argument("--plant", choices=("arena", "rotorpy"), default="arena", help="the vehicle the runs fly on")
    common(rules)
    rules.set_defaults(func=_cmd_rules)

    env = ssub.add_parser("envelope", help="design a grid of flips and map feasibility, duration, height, conditioning")
    env.add_argument("--flips", default="1,2,3,4", help="flip counts, e.g. 1,2,3,4")
    env.add_argument("--rates-deg-s", default="600:2000:8", help="max rates A:B:N or a comma list [deg/s]")
    env.add_argument("--dims", type=int, choices=(2, 3), default=2)
    env.add_argument("--axis", choices=("roll", "pitch"), default="roll")
    env.add_argument("--vehicle", default="hummingbird")
    common(env)
    env.set_defaults(func=_cmd_envelope)
