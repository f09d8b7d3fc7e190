"""``aerobat study``: robustness over sampled vehicles, update rules side by side, design envelopes.

Every study: its id is printed before the first job runs; progress is one line per
finished job (with an ETA) whether or not the output is a terminal; each job's
outcome is committed as it arrives; failed jobs are listed with their errors and
make the command exit 1; ``--resume STUDY`` runs what is not done (failed jobs
included) and writes where the study wrote.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import shlex
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.cli.common import (
    CommandFailed,
    HelpFormatter,
    add_db_option,
    add_design_model_option,
    add_maneuver_options,
    add_plant_options,
    add_tune_option,
    bounded_int,
    check_outputs,
    console,
    each_of,
    finite_float,
    maneuver_from_args,
    old_spelling,
    open_store,
    output_dir,
    plant_choice_from_args,
    plant_settings_path,
    session_ref,
    text_path,
)
from aerobat.cli.stopping import Stopped, sigterm_stops
from aerobat.cli.tune_options import with_tune_from_args
from aerobat.core.bounds import choices_of
from aerobat.errors import ConfigError, DesignFailed
from aerobat.quadrotor.feedback import FeedbackScheme
from aerobat.quadrotor.maneuvers.flip import DIMS, Axis

__all__ = ["add_execution_options", "register", "report_failures", "run_cli_study"]


def trials_text(trials: float) -> str:
    """A median number of trials to the tolerance as a person reads it: ``never`` when most runs did not get there."""
    return f"{trials:g}" if math.isfinite(trials) else "never"


def _study_folder(args: argparse.Namespace, store: Any, study_id: int, written: tuple[str, ...]) -> Path:
    """The study's folder, claimed and recorded in the store as soon as the study starts (issue 31 D8).

    ``--out``, else the folder recorded when the study started (so ``--resume`` after a kill
    writes where it began), else ``out/<store>-<hash>/study-ID``. Every file the study writes at
    the end is checked now, before any job runs.
    """
    from aerobat.fileio import claim_folder, default_folder, folder_owner

    record = store.study(study_id)
    owner = folder_owner(store.path, "study", study_id, record.created_at)
    chosen = args.out if args.out is not None else record.out_dir
    named = chosen is not None
    if chosen is None:
        chosen = default_folder(store.path, "study", study_id, record.created_at)
    out = claim_folder(text_path(chosen, "--out"), owner, option="--out", force=named)
    check_outputs({out / name: "--out" for name in written}, stores=(store.path,))
    if record.out_dir != str(out):
        store.set_study_out_dir(study_id, str(out))
    return out


def study_eta(elapsed_s: float, ran: int, remaining: int, job_walls_s: list[float], workers: int | None) -> float:
    """Seconds left, from the jobs measured so far.

    A job's own wall time (``wall_s``, measured in its worker) excludes starting the pool and
    loading the compiled kernels, which the time since the start includes and which the first
    job would otherwise spread over all the others (an estimate 14 times too long). With
    ``workers`` running side by side, the rest takes their mean time per round of ``workers``
    jobs. Without measured job times or a known pool size, the rate since the start is used.
    """
    if remaining <= 0:
        return 0.0
    if job_walls_s and workers:
        mean = sum(job_walls_s) / len(job_walls_s)
        return mean * math.ceil(remaining / workers)
    return elapsed_s / ran * remaining if ran else math.nan




def crowding_note(workers: int | None, cores: int, cpu_count: int) -> str:
    """A line when ``workers`` jobs whose plants keep ``cores`` cores busy each need more cores than there are."""
    if workers is None or cores <= 1 or workers * cores <= cpu_count:
        return ""
    return (f"note: {workers} jobs at a time, each keeping {cores} cores busy (a Betaflight firmware over spinning "
            f"shared memory), on {cpu_count} cores: they take the cores from each other and the study runs "
            f"slower than with --workers {max(1, cpu_count // cores)} (docs/performance.md, issue 27)")


def _check_out(args: argparse.Namespace, written: tuple[str, ...]) -> None:
    """An unusable --out (the store itself, a file, no text) is refused before anything runs (the design included)."""
    if args.out is not None:
        folder = output_dir(text_path(args.out, "--out"))
        check_outputs({folder / name: "--out" for name in written}, stores=(getattr(args, "db", None),))


def run_cli_study(args: argparse.Namespace, kind: str, run: Callable[..., Any],
                  written: tuple[str, ...] = (), *, cores: int = 1, design: Any = None) -> tuple[Any, Path]:
    """Run a study with progress lines; returns (what ``run`` returned, output folder).

    ``run(store, **options)`` runs the study (one of :mod:`aerobat.experiments.studies.run_and_report`'s
    calls, or :func:`~aerobat.experiments.studies.runner.run_study` bound to a specification and
    jobs) with the options of :func:`~aerobat.experiments.studies.runner.run_study`. Failed jobs are
    the caller's to report. ``written``: the files the caller writes into the folder afterwards
    (checked before any job runs). ``cores``: the cores one job's plant keeps busy
    (:meth:`~aerobat.plants.PlantChoice.cores`): without ``--workers``, the machine's cores ÷ ``cores``
    jobs run at once, as :func:`~aerobat.experiments.studies.runner.run_study` decides from the jobs.
    ``design``: the study's :class:`~aerobat.experiments.designing.NominalDesign`, said once the study starts.
    """
    _check_out(args, written)
    out_console = console(getattr(args, "json", False))
    progress_console = console(True)  # standard error
    started = time.perf_counter()
    state: dict[str, Any] = {"first": 0, "walls": []}
    from aerobat.experiments.execution import default_workers

    workers = None if args.scheduler is not None else (args.workers or default_workers(cores))
    crowded = crowding_note(workers, cores, os.cpu_count() or 1)
    if crowded:
        out_console.print(crowded, soft_wrap=True)

    def on_start(study_id: int, todo: int, done: int) -> None:
        state["first"] = done
        state["study"] = study_id
        state["total"] = todo + done
        state["out"] = _study_folder(args, store, study_id, written)
        at_once = "" if workers is None else f", {workers} at a time"
        out_console.print(f"study {study_id} ({kind}): {todo} jobs to run, {done} already done "
                          f"(resume with --resume {study_id}){at_once}", soft_wrap=True)
        if design is not None:
            out_console.print(f"  {_designed_on(design)}", soft_wrap=True)
        out_console.file.flush()

    def progress(done: int, total: int, job: Any, outcome: Any) -> None:
        ran = done - state["first"]
        elapsed = time.perf_counter() - started
        wall = (outcome.result or {}).get("wall_s") if outcome.done else None
        if isinstance(wall, int | float) and math.isfinite(wall) and wall >= 0:
            state["walls"].append(float(wall))
        eta = study_eta(elapsed, ran, total - done, state["walls"], workers)
        note = "" if outcome.done else f" FAILED: {outcome.error}"
        # progress on standard error (docs/cli.md): standard output keeps what the study found
        progress_console.print(f"  [{done}/{total}] {job.key} {outcome.status.value}{note} "
                               f"(elapsed {elapsed:.0f} s, about {eta:.0f} s left)", soft_wrap=True)
        progress_console.file.flush()

    with open_store(args) as store, sigterm_stops(standalone=getattr(args, "standalone", False)):
        try:
            result = run(store, resume=args.resume, workers=args.workers, scheduler=args.scheduler,
                         progress=progress, on_start=on_start, command=args.argv)
        except KeyboardInterrupt as exc:  # SIGINT or SIGTERM: every finished job is stored, the workers ended
            if "study" not in state:
                raise
            signum = getattr(exc, "signum", signal.SIGINT)
            study_id, total = state["study"], state["total"]
            done = len(store.finished_study_jobs(study_id))
            raise Stopped(signum, f"interrupted by {signal.Signals(signum).name}: study {study_id} stopped with "
                                  f"{done} of {total} jobs stored; resume with: "
                                  f"{_resume_command(getattr(args, 'argv', None), study_id)}") from None
        out = state.get("out") or _study_folder(args, store, result.study_id, written)
    return result, out


def _resume_command(argv: list[str] | None, study_id: int) -> str:
    """The command line that resumes the study: the one given, its ``--resume`` replaced."""
    if not argv:
        return f"the same command with --resume {study_id}"
    words: list[str] = []
    skip = False
    for word in argv:
        if skip:
            skip = False
        elif word == "--resume":
            skip = True
        elif not word.startswith("--resume="):
            words.append(word)
    return shlex.join(["aerobat", *words, "--resume", str(study_id)])


def _stoppable(command: Any) -> Any:
    """The study command, with SIGTERM ending it like Ctrl-C (:mod:`aerobat.cli.stopping`)."""

    @functools.wraps(command)
    def run(args: argparse.Namespace) -> int:
        with sigterm_stops(standalone=getattr(args, "standalone", False)):
            return int(command(args))

    return run


def report_failures(outcome: Any) -> None:
    if outcome.failed:
        lines = "; ".join(f"{f.key}: {f.error}" for f in outcome.failed[:5])
        more = f" (and {len(outcome.failed) - 5} more)" if len(outcome.failed) > 5 else ""
        raise CommandFailed(f"study {outcome.study_id}: {len(outcome.failed)} of {outcome.total} jobs failed: "
                            f"{lines}{more}; run them again with --resume {outcome.study_id}")


def _design(args: argparse.Namespace, plant: Any, written: tuple[str, ...]) -> tuple[Any, Any, Any]:
    """The study's nominal design for ``plant`` (a :class:`~aerobat.experiments.designing.NominalDesign`), after
    checking ``--out`` for the files ``written`` there."""
    from aerobat.experiments.designing import nominal_design

    _check_out(args, written)
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = maneuver_from_args(args, config)
    nominal = nominal_design(maneuver, config, plant=plant, design_model=getattr(args, "design_model", None),
                             correction=args.correction)
    if not nominal.design.converged:
        raise DesignFailed(f"design failed on the {nominal.model.value} model: {nominal.design.message}",
                           nominal.design)
    return config, maneuver, nominal


def _designed_on(nominal: Any) -> str:
    """One line: the model a study's design ran on, and how long it took."""
    from aerobat.plants import DesignModel

    model = (nominal.description if nominal.model is DesignModel.PAPER
             else f"the {nominal.model.value} model ({nominal.description})")
    return f"designed on {model} in {nominal.compute_s:.1f} s"


# ----------------------------------------------------------------- robustness


def _sampled_plants() -> tuple[str, ...]:
    from aerobat.plants import sampled_plants

    return sampled_plants()


def _spec(plant: str) -> Any:
    from aerobat.plants import PLANTS

    return PLANTS.get(plant, source="--plant")


def _studied_plants() -> tuple[str, ...]:
    from aerobat.plants import studied_plants

    return studied_plants()


def _scenarios_of(plant: str) -> tuple[str, ...]:
    """The feedback study's scenarios the plant ``plant`` declares (``default`` first)."""
    from aerobat.plants import PLANTS

    return tuple(s.name for s in PLANTS.get(plant, source="--plant").scenarios)


def _cmd_robustness(args: argparse.Namespace) -> int:
    from aerobat.core.rules import RuleChoice
    from aerobat.experiments.studies import RobustnessRanges, load_ranges, robustness_study
    from aerobat.plants import PlantChoice

    rule = RuleChoice.parse(args.rule, source="--rule")
    if args.ranges is not None and not args.ranges.strip():  # it was ignored: the default ranges ran
        raise ConfigError("--ranges: empty file name")
    ranges = load_ranges(args.ranges) if args.ranges is not None else RobustnessRanges()
    # the settings every vehicle is sampled around: the plant's file and tune where given (a plant that flies
    # a tune always samples around its settings: aerobat's own tune when none is given), else its defaults
    path = plant_settings_path(args)
    chosen = with_tune_from_args(args, PlantChoice.from_file(args.plant, path))
    base = chosen.settings if path is not None or chosen.spec.tune is not None else None
    written = ("trials_to_tolerance.png", "success_vs_property.png", "robustness.json")
    config, maneuver, nominal = _design(args, PlantChoice(args.plant, base), written)
    run = functools.partial(robustness_study, maneuver=maneuver, design=nominal, model=config,
                            vehicles=args.vehicles, iterations=args.iterations, seed=args.seed, ranges=ranges,
                            rule=rule, tolerance_m=args.tolerance_m, plant=args.plant, base=base,
                            feedback=args.feedback)
    study, out = run_cli_study(args, "robustness", run, written=written, cores=PlantChoice(args.plant, base).cores(),
                               design=nominal)
    outcome = study.outcome
    study.write(out)
    summary = study.summary
    if args.json:
        print(json.dumps(study.to_json()))
    else:
        c = console()
        c.print(f"study {outcome.study_id}: {summary.completed}/{args.vehicles} vehicles learned "
                f"({outcome.ran} run now, {outcome.skipped} already done, {len(outcome.failed)} failed)")
        c.print(f"success (mean of the last 10 position errors ≤ {args.tolerance_m:g} m): "
                f"{100 * summary.success_rate:.1f} % of the vehicles learned")
        c.print(f"median trials to {args.tolerance_m:g} m: {trials_text(summary.median_trials_to_tolerance)}")
        if summary.predictors:
            c.print("properties most correlated with failure: " + ", ".join(
                f"{name} ({corr:+.2f})" for name, corr in summary.predictors[:4]))
        c.print(f"figures and robustness.json in {out}/")
    report_failures(outcome)
    return 0


# ------------------------------------------------------------------ envelope


def _parse_list(text: str, option: str, cast: Any) -> list:
    try:
        if ":" in text:
            a, b, n = text.split(":")
            if cast is float:
                values = list(np.linspace(float(a), float(b), int(n)))
            else:
                values = list(range(int(a), int(b) + 1, max(1, int(n))))
        else:
            values = [cast(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(f"{option} {text!r}: expected a comma list or A:B:N") from None
    if not values or len(values) > 500 or not all(math.isfinite(float(v)) for v in values):
        raise ConfigError(f"{option} {text!r}: expected 1 … 500 finite values")
    return values


def _cmd_envelope(args: argparse.Namespace) -> int:
    from aerobat.experiments.studies import check_envelope_grid, envelope_study
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    # the study's own check, before the store is opened
    flips, rates = check_envelope_grid(_parse_list(args.flips, "--flips", int),
                                       _parse_list(args.rates_deg_s, "--rates-deg-s", float))
    config = vehicle_from_name_or_file(args.vehicle)
    run = functools.partial(envelope_study, model=config, flips=flips, rates_deg_s=rates, dims=args.dims,
                            axis=args.axis)
    study, out = run_cli_study(args, "envelope", run, written=("envelope.json", "envelope_feasible.png"))
    outcome = study.outcome
    study.write(out)
    feasible = study.feasible
    report = {"study": outcome.study_id, "feasible": int(np.nansum(feasible)), "designs": int(feasible.size),
              "failed_jobs": len(outcome.failed), "cells": study.to_json()}
    if args.json:
        print(json.dumps(report))
    else:
        console().print(f"study {outcome.study_id}: {int(np.nansum(feasible))}/{feasible.size} designs feasible "
                        f"({outcome.ran} run now, {outcome.skipped} already done, {len(outcome.failed)} failed); "
                        f"figures and envelope.json in {out}/")
    report_failures(outcome)
    return 0


# ------------------------------------------------------------------ rules


def _cmd_rules(args: argparse.Namespace) -> int:
    from aerobat.experiments.baselines import check_methods
    from aerobat.experiments.studies import parse_methods, rules_study

    methods = parse_methods(args.methods)
    plant = plant_choice_from_args(args)
    check_methods(methods)  # every method's package is there before a single job runs
    plant.spec.check_available()
    config, maneuver, nominal = _design(args, plant, ("rules.csv", "rules.png"))
    run = functools.partial(rules_study, maneuver=maneuver, design=nominal, model=config, methods=methods,
                            seeds=args.seeds, trials=args.trials, plant=plant, tolerance_m=args.tolerance_m)
    study, out = run_cli_study(args, "rules", run, written=("rules.csv", "rules.png"), cores=plant.cores(),
                               design=nominal)
    outcome = study.outcome
    study.write(out)
    rows = study.rows
    if args.json:
        print(json.dumps({"study": outcome.study_id, "methods": [dataclasses.asdict(r) for r in rows]}))
    else:
        from rich.table import Table

        table = Table(title=f"study {outcome.study_id}: {maneuver.name}, {args.seeds} seeds × {args.trials} trials")
        for col in ("method", f"median trials to {args.tolerance_m:g} m", "reached", "below after",
                    "last-10 [m]", "failed", "s/run"):
            table.add_column(col, justify="right" if col != "method" else "left")
        for r in rows:
            share = r.share_below_after
            table.add_row(r.method, trials_text(r.median_trials_to_tolerance), f"{r.reached}/{r.runs}",
                          "—" if math.isnan(share) else f"{100 * share:.0f} %", f"{r.last10_mean_m:.3f}",
                          str(r.failures), f"{r.wall_s:.1f}")
        c = console()
        c.print(table)
        for r in rows:
            for error in r.job_errors:
                c.print(f"{r.method}: a job failed: {error}")
        c.print(f"({outcome.ran} runs now, {outcome.skipped} already done); rules.csv and rules.png in {out}/")
    report_failures(outcome)
    return 0


# ------------------------------------------------------------------ feedback


def _cmd_feedback(args: argparse.Namespace) -> int:
    from aerobat.experiments.studies import feedback_study, parse_scenarios, parse_schemes
    from aerobat.quadrotor.feedback import Feedback

    schemes = parse_schemes(args.schemes)
    scenarios = (parse_scenarios(args.scenarios, plant=args.plant) if args.scenarios is not None
                 else list(_scenarios_of(args.plant)))
    plant = plant_choice_from_args(args)
    plant.spec.check_available()
    for scheme in schemes:
        plant.spec.check_feedback(Feedback(scheme))
    config, maneuver, nominal = _design(args, plant, ("feedback.csv", "feedback.png"))
    run = functools.partial(feedback_study, maneuver=maneuver, design=nominal, model=config, schemes=schemes,
                            scenarios=scenarios, seeds=args.seeds, trials=args.trials, plant=plant, rule=args.rule,
                            tolerance_m=args.tolerance_m)
    study, out = run_cli_study(args, "feedback", run, written=("feedback.csv", "feedback.png"),
                               cores=plant.cores(), design=nominal)
    outcome = study.outcome
    study.write(out)
    rows = study.rows
    if args.json:
        print(json.dumps({"study": outcome.study_id, "rows": [dataclasses.asdict(r) for r in rows]}))
    else:
        from rich.table import Table

        table = Table(title=f"study {outcome.study_id}: {maneuver.name}, {args.seeds} seeds × {args.trials} "
                            f"trials, rule {args.rule}")
        for col in ("scenario", "scheme", "last-10 [m]", "worst seed", "angles [°]",
                    f"median to {args.tolerance_m:g} m", "failed", "ms/trial"):
            table.add_column(col, justify="left" if col in ("scenario", "scheme") else "right")
        for r in rows:
            angles = "/".join(f"{a:.2f}" for a in r.last10_angle_deg) or "—"
            table.add_row(r.scenario, r.scheme, f"{r.last10_mean_m:.3f}", f"{r.last10_worst_seed_m:.3f}",
                          angles, trials_text(r.median_trials_to_tolerance), f"{r.failures}/{r.runs}",
                          f"{r.wall_ms_per_trial:.1f}")
        c = console()
        c.print(table)
        for r in rows:
            for error in r.job_errors:
                c.print(f"{r.scenario}/{r.scheme}: a job failed: {error}")
        c.print(f"({outcome.ran} runs now, {outcome.skipped} already done); feedback.csv and feedback.png in {out}/")
    report_failures(outcome)
    return 0


# ------------------------------------------------------------------ parser


def add_execution_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler address tcp://HOST:PORT (default: $DASK_SCHEDULER_ADDRESS, else local)")
    p.add_argument("--workers", type=bounded_int(1, 1024), default=None,
                   help="local worker processes (default: all cores; half of them for a Betaflight plant "
                        "over spinning shared memory, whose instances keep two cores each)")
    p.add_argument("--resume", default=None, metavar="STUDY", type=session_ref,
                   help="continue a study (id or 'last'): run only the jobs not done, failed ones included "
                        "(default: a new study)")
    p.add_argument("--out", default=None, help="folder for figures and the report "
                                               "(default: out/STORE-HASH/study-ID, one per store and study)")
    add_db_option(p)


def register(sub: Any) -> None:
    fmt = HelpFormatter
    study = sub.add_parser("study", help="robustness, rules, feedback and envelope studies, on a local pool or Dask",
                           formatter_class=fmt)
    ssub = study.add_subparsers(dest="study", parser_class=type(study), metavar="STUDY")

    rob = ssub.add_parser("robustness", help="learn one maneuver on K sampled vehicles", formatter_class=fmt)
    add_maneuver_options(rob)
    rob.add_argument("--vehicles", type=bounded_int(1, 100000), default=100, help="number of sampled vehicles K")
    rob.add_argument("--trials", dest="iterations", type=bounded_int(1, 1000), default=30,
                     help="measured trials per vehicle")
    old_spelling(rob, "--iterations", "iterations", type=bounded_int(1, 1000))
    rob.add_argument("--seed", type=bounded_int(0, 2**40), default=0, help="seed of the vehicle sampling")
    rob.add_argument("--rule", default="paper", help="update rule (see docs/method.md)")
    rob.add_argument("--tolerance-m", type=finite_float(1e-6, 100.0, "m"), default=0.12,
                     help="position tolerance of success [m]")
    rob.add_argument("--ranges", metavar="FILE.toml",
                     help="sampling ranges, a [ranges] table (default: docs/plants.md's)")
    rob.add_argument("--plant", choices=_sampled_plants(), default="arena",
                     help="whose true vehicle is sampled: a plant whose spec says how (docs/plants.md says what "
                          "varies)")
    rob.add_argument("--feedback", choices=choices_of(FeedbackScheme), default=None,
                     help="onboard feedback of every vehicle, see docs/feedback.md "
                          "(default: the plant's best measured)")
    for name in _sampled_plants():
        spec = _spec(name)
        if spec.option is not None:
            rob.add_argument(spec.option, metavar="FILE.toml",
                             help=f"{name} plant settings to sample around, only with --plant {name} (default: the "
                                  f"shipped ones)")
    add_tune_option(rob, _sampled_plants(), flown_by="every sampled vehicle")
    add_design_model_option(rob)
    add_execution_options(rob)
    rob.set_defaults(func=_stoppable(_cmd_robustness))

    rules = ssub.add_parser("rules", help="every update rule and two model-free baselines, side by side",
                            formatter_class=fmt)
    add_maneuver_options(rules)
    rules.add_argument("--methods", metavar="LIST", default=",".join(_default_methods()),
                       help="comma list of rules and baselines")
    rules.add_argument("--seeds", type=bounded_int(1, 1000), default=20, help="plant seeds per method")
    rules.add_argument("--trials", type=bounded_int(2, 1000), default=30, help="measured trials per run")
    rules.add_argument("--tolerance-m", type=finite_float(1e-6, 100.0, "m"), default=0.12,
                       help="position tolerance [m]")
    add_plant_options(rules, kinds=_studied_plants())
    rules.set_defaults(seed=0)
    add_execution_options(rules)
    rules.set_defaults(func=_stoppable(_cmd_rules))

    fb = ssub.add_parser("feedback", help="open loop and each onboard feedback scheme side by side, across "
                         "scenarios", formatter_class=fmt)
    add_maneuver_options(fb)
    fb.add_argument("--schemes", metavar="LIST", default=",".join(choices_of(FeedbackScheme)),
                    help="comma list of feedback schemes")
    fb.add_argument("--scenarios", metavar="LIST", default=None,
                    help="comma list of the plant's scenarios, docs/feedback.md (default: every scenario the plant "
                         "has; the arena's: " + ",".join(_scenarios_of("arena")) + ")")
    fb.add_argument("--seeds", type=bounded_int(1, 1000), default=20, help="plant seeds per scheme and scenario")
    fb.add_argument("--trials", type=bounded_int(2, 1000), default=30, help="measured trials per run")
    fb.add_argument("--rule", default="paper", help="update rule (see docs/method.md)")
    fb.add_argument("--tolerance-m", type=finite_float(1e-6, 100.0, "m"), default=0.12,
                    help="position tolerance [m]")
    add_plant_options(fb, kinds=_studied_plants(), feedback=False)  # --schemes says which
    fb.set_defaults(seed=0)
    add_execution_options(fb)
    fb.set_defaults(func=_stoppable(_cmd_feedback))

    env = ssub.add_parser("envelope", help="design a grid of flips and map feasibility, duration, height, "
                          "conditioning", formatter_class=fmt)
    env.add_argument("--flips", default="1,2,3,4", metavar="LIST", help="flip counts, e.g. 1,2,3,4")
    env.add_argument("--rates-deg-s", default="600:2000:8", metavar="A:B:N|LIST",
                     help="max rates A:B:N or a comma list [deg/s]")
    env.add_argument("--dims", type=int, choices=each_of(DIMS), default=2, help="2D or 3D flips")
    env.add_argument("--axis", choices=choices_of(Axis), default="roll", help="flip axis")
    env.add_argument("--vehicle", default="hummingbird", help="design vehicle: preset or TOML file")
    env.add_argument("--json", action="store_true", help="print one JSON object")
    add_execution_options(env)
    env.set_defaults(func=_stoppable(_cmd_envelope))


def _default_methods() -> tuple[str, ...]:
    from aerobat.experiments.studies.rules import DEFAULT_METHODS

    return DEFAULT_METHODS
