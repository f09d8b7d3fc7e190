"""The ``aerobat`` command.

Every command turns bad input into a one-line ``aerobat: error: …`` message and
exit status 2 (``--debug`` shows the traceback instead); a solver or plant that
fails exits with status 1 and says why.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from .config import ConfigError

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


class CommandFailed(RuntimeError):
    """A command ran but its result is a failure (non-converged solve, crashed plant…)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, documented exit code
        self.exit(EXIT_USAGE, f"aerobat: error: {message}\n")


def _console(json_mode: bool):
    from rich.console import Console

    stream = sys.stderr if json_mode else sys.stdout
    width = None if stream.isatty() else 160  # keep tables readable in logs and pipes
    return Console(stderr=json_mode, highlight=False, markup=False, width=width)


# ------------------------------------------------------------------ simulate


def _cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from .program import load_program
    from .simulate import final_state_summary, simulate
    from .vehicle import vehicle_from_name_or_file

    program = load_program(args.program)
    config = vehicle_from_name_or_file(args.vehicle)
    traj = simulate(program, config, mode=args.mode)
    if not np.all(np.isfinite(traj.final_state)):
        raise CommandFailed("simulation produced non-finite states")
    summary = final_state_summary(traj.final_state, traj.duration_s)
    if args.plot:
        from .plotting import plot_trajectory

        plot_trajectory(traj.times_s, traj.states, traj.commands, args.plot,
                        title=f"{program.name or Path(args.program).stem} on {config.name}")
    if args.json:
        print(json.dumps(summary))
    else:
        _print_state_table(summary, title=f"{args.program} on {config.name} ({args.mode})")
        if args.plot:
            print(f"plot written to {args.plot}")
    return EXIT_OK


def _print_state_table(summary: dict[str, Any], *, title: str) -> None:
    import math

    from rich.table import Table

    fs = summary["final_state"]
    table = Table(title=title)
    table.add_column("quantity")
    for axis in ("x / φ", "y / θ", "z / ψ"):
        table.add_column(axis, justify="right")
    table.add_row("position [m]", *(f"{v:+.4f}" for v in fs["position_m"]))
    table.add_row("velocity [m/s]", *(f"{v:+.4f}" for v in fs["velocity_m_s"]))
    table.add_row("Euler ZYX [°]", *(f"{math.degrees(v):+.2f}" for v in fs["euler_zyx_rad"]))
    table.add_row("rotation, unwrapped [°]", *(f"{math.degrees(v):+.2f}" for v in fs["rotation_angle_rad"]))
    _console(False).print(table)
    print(f"duration: {summary['duration_s']:.4f} s")


# ---------------------------------------------------------- maneuvers, plants


def _maneuver_from_args(args: argparse.Namespace, config):
    import math

    from .maneuvers import MultiFlip

    if args.maneuver == "flip":
        return MultiFlip(
            vehicle=config.vehicle,
            flips=args.flips,
            max_rate_rad_s=math.radians(args.max_rate_deg_s),
            axis=args.axis,
            dims=args.dims,
            coast_collective=args.coast,
            ramp_collective_s=args.ramp_s,
        )
    if args.maneuver == "translation":
        from .maneuvers.translation import translation_maneuver

        try:
            return translation_maneuver(config, _parse_pair(args.to, "--to"), final_angle_rad=args.final_angle_rad)
        except RuntimeError as exc:  # the benchmark solve failed: say so, exit 1
            raise CommandFailed(str(exc)) from None
    raise ValueError(f"unknown maneuver {args.maneuver!r}")


def _parse_pair(text: str, option: str) -> tuple[float, float]:
    import math

    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{option} {text!r}: expected two numbers Y,Z in metres") from None
    if len(values) != 2 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{option} {text!r}: expected two finite numbers Y,Z in metres")
    return values  # type: ignore[return-value]


def _plant_from_args(args: argparse.Namespace, config):
    from .plants import Arena, ArenaParams, NominalPlant, load_arena

    if args.plant == "nominal":
        return NominalPlant(config)
    if args.plant == "arena":
        params = load_arena(args.arena) if args.arena else ArenaParams()
        return Arena(config, params, seed=args.seed)
    if args.plant == "rotorpy":
        from .plants.rotorpy import RotorPyPlant

        return RotorPyPlant(config, settings_path=getattr(args, "rotorpy", None), seed=args.seed)
    raise ValueError(f"--plant {args.plant!r}: allowed nominal, arena, rotorpy")


def _design_from_args(args: argparse.Namespace, config, maneuver):
    from .design import design
    from .simulate import NominalModel

    return design(maneuver, NominalModel(config), correction=args.correction)


# ------------------------------------------------------------------ design


def _cmd_design(args: argparse.Namespace) -> int:
    from .vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = _maneuver_from_args(args, config)
    result = _design_from_args(args, config, maneuver)
    if args.json:
        print(json.dumps(result.to_json_dict()))
    else:
        _print_design(result)
    if not result.converged:
        raise CommandFailed(result.message)
    return EXIT_OK


def _print_design(result) -> None:
    import numpy as np
    from rich.table import Table

    console = _console(False)
    m = result.maneuver
    table = Table(title=f"design: {m.name}")
    for col in ("parameter", "meaning", "unit", "guess p^g", "nominal p⁰"):
        table.add_column(col, justify="right" if "p" in col and col != "parameter" else "left")
    for spec, g, p in zip(m.parameters, result.p_guess, result.p_nominal, strict=True):
        table.add_row(spec.name, spec.description, spec.unit, f"{g:.5g}", f"{p:.5g}")
    console.print(table)
    console.print(f"status: {result.status} — {result.message}")
    console.print(f"residual norm: {result.residual_norm:.3g}   duration (ramps included): {result.duration_s:.4f} s")
    console.print(f"condition number (scaled J): {result.condition_number:.3g}   correction: {result.correction_kind}")
    console.print("singular values: " + np.array2string(result.singular_values, precision=4))
    with np.printoptions(precision=4, suppress=False, linewidth=140):
        console.print(f"J (rows: {', '.join(e.name for e in m.errors)}):\n{result.jacobian}")
        console.print(f"C:\n{result.correction}")
    console.print(f"compute time: {result.compute_s * 1000:.0f} ms")


# ------------------------------------------------------------------ learn


@dataclass(frozen=True)
class _LearnRun:
    """Everything one ``learn`` invocation flies: a new session or a resumed one."""

    session_id: int
    db: str
    maneuver: Any
    design: Any
    model_config: Any
    plant: Any
    seed: int | None
    rule: Any
    start_params: Any
    start_correction: int
    start_index: int
    measured: int
    target: int
    resumed: bool
    exact: bool


def _cmd_learn(args: argparse.Namespace) -> int:
    from .store import Store, default_path

    if args.resume is not None and args.from_session is not None:
        raise ValueError("--resume and --from-session exclude each other: --resume continues a session, "
                         "--from-session starts a new one from another session's learned parameters")
    if args.iterations is not None and not 1 <= args.iterations <= 10000:
        raise ValueError(f"--iterations {args.iterations}: allowed 1 … 10000")
    if args.resume is None and args.maneuver is None:
        raise ValueError("learn: name a maneuver (flip or translation), or continue a stored session with "
                         "--resume SESSION")
    db = default_path() if args.db is None else args.db
    if args.resume is None:
        # everything cheap is checked before the store is touched and before the (long) design
        from .vehicle import vehicle_from_name_or_file

        config = vehicle_from_name_or_file(args.vehicle)
        maneuver = _maneuver_from_args(args, config)
        schedule = _schedule_table(args.gamma)
        plant_kind, plant_config = _plant_config(args)
    with Store(db, synchronous="full" if args.fsync else "normal") as store:
        Path(args.out).mkdir(parents=True, exist_ok=True)  # an unusable --out fails now, not after learning
        if args.resume is None:
            run = _new_run(store, args, db, config, maneuver, schedule, plant_kind, plant_config)
        else:
            run = _resumed_run(store, args, db)
        return _run_learning(store, run, args)


def _schedule_table(text: str) -> dict[str, Any]:
    if text == "paper":
        return {"kind": "paper", "minimum": 0.1}
    return {"kind": "constant", "value": _gamma_value(text)}


def _rule_from_table(table: dict[str, Any], design, source: str, *, maneuver=None, config=None):
    """The update rule a session uses: ``{"name": rule, "schedule": {...}}`` (see docs/method.md)."""
    from .learning import ConstantSchedule, CorrectionRule, PaperSchedule

    schedule = table.get("schedule", {}) if isinstance(table, dict) else None
    name = table.get("name") if isinstance(table, dict) else None
    if not isinstance(schedule, dict) or not isinstance(name, str):
        raise ConfigError(f"{source}: update rule {table!r}: expected a name and a schedule")
    fixed: PaperSchedule | ConstantSchedule | None
    if schedule.get("kind") == "paper":
        fixed = PaperSchedule(float(schedule.get("minimum", 0.1)))
    elif schedule.get("kind") == "constant":
        fixed = ConstantSchedule(float(schedule["value"]))
    elif schedule.get("kind") == "rule":
        fixed = None  # the rule's own step sizes
    else:
        raise ConfigError(f"{source}: step-size schedule {schedule!r}: expected kind 'paper', 'constant' or 'rule'")
    if name == "paper":
        return CorrectionRule(design.correction, fixed or PaperSchedule())
    from .rules import RULE_NAMES, make_rule

    base = name.removesuffix("+isc")
    if base not in RULE_NAMES:
        raise ConfigError(f"{source}: unknown update rule {name!r}; allowed: {', '.join(RULE_NAMES)} "
                          f"(optionally with '+isc')")
    options: dict[str, Any] = {}
    if name.endswith("+isc"):
        from .rules_quadrotor import quadrotor_isc

        options["sensitivity"], options["deviation"] = quadrotor_isc(maneuver, config, design.p_nominal)
    try:
        return make_rule(name, design, schedule=fixed, **options)
    except ValueError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def _rule_table(args: argparse.Namespace) -> dict[str, Any]:
    """``--rule`` and ``--gamma`` as stored: the paper's rule defaults to the paper's schedule,
    the other rules to their own step sizes unless ``--gamma`` is given."""
    if args.rule == "paper" or args.gamma != "paper":
        return {"name": args.rule, "schedule": _schedule_table(args.gamma)}
    return {"name": args.rule, "schedule": {"kind": "rule"}}


def _gamma_value(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--gamma {text!r}: use 'paper' or a number in (0, 1]") from None
    if not 0.0 < value <= 1.0:
        raise ValueError(f"--gamma {value}: allowed (0, 1]")
    return value


def _vehicle_table(config) -> dict[str, Any]:
    from .config import dataclass_to_table

    return {"name": config.name, "vehicle": dataclass_to_table(config.vehicle),
            "controller": dataclass_to_table(config.controller)}


def _vehicle_from_table(table: dict[str, Any], source: str):
    from .config import dataclass_from_table
    from .vehicle import ControllerParams, VehicleConfig, VehicleParams

    if not isinstance(table, dict) or "vehicle" not in table or "controller" not in table:
        raise ConfigError(f"{source}: expected a table with vehicle and controller")
    return VehicleConfig(
        vehicle=dataclass_from_table(VehicleParams, table["vehicle"], source=f"{source}.vehicle"),
        controller=dataclass_from_table(ControllerParams, table["controller"], source=f"{source}.controller"),
        name=str(table.get("name", "custom")),
    )


def _plant_config(args: argparse.Namespace) -> tuple[str, dict[str, Any]]:
    """The plant's kind and settings table (the arena file is read and checked here)."""
    from .config import dataclass_to_table
    from .plants import ArenaParams, load_arena

    if args.plant == "nominal":
        return "nominal", {}
    if args.plant == "arena":
        return "arena", {"arena": dataclass_to_table(load_arena(args.arena) if args.arena else ArenaParams())}
    if args.plant == "rotorpy":
        settings = getattr(args, "rotorpy", None)
        return "rotorpy", {"settings": str(Path(settings).resolve()) if settings else None}
    raise ValueError(f"--plant {args.plant!r}: allowed nominal, arena, rotorpy")


def _build_plant(kind: str, table: dict[str, Any], config, seed: int | None, source: str):
    from .config import dataclass_from_table
    from .plants import Arena, ArenaParams, NominalPlant

    if kind == "nominal":
        return NominalPlant(config)
    if kind == "arena":
        params = dataclass_from_table(ArenaParams, table.get("arena", {}), source=f"{source}.arena")
        return Arena(config, params, seed=seed or 0)
    if kind == "rotorpy":
        from .plants.rotorpy import RotorPyPlant

        return RotorPyPlant(config, settings_path=table.get("settings"), seed=seed or 0)
    raise ConfigError(f"{source}: unknown plant kind {kind!r}")


def _spec_difference(stored: dict[str, Any], given: dict[str, Any]) -> str:
    keys = sorted(set(stored) | set(given))
    diffs = [f"{k} = {stored.get(k)!r} (stored) vs {given.get(k)!r}" for k in keys
             if json.dumps(stored.get(k), sort_keys=True) != json.dumps(given.get(k), sort_keys=True)]
    return "; ".join(d if len(d) < 160 else d[:157] + "…" for d in diffs[:4])


def _new_run(store, args, db: str, config, maneuver, schedule, plant_kind, plant_config) -> _LearnRun:
    import numpy as np

    start_params = None
    warm_from = None
    if args.from_session is not None:
        source_id = store.resolve_session(args.from_session)
        source = store.session(source_id)
        stored_spec = store.maneuver(source.maneuver_id).spec
        given_spec = json.loads(json.dumps(maneuver.spec()))
        if json.dumps(stored_spec, sort_keys=True) != json.dumps(given_spec, sort_keys=True):
            raise ValueError(f"--from-session {source_id}: session {source_id} learned '{source.maneuver_name}', "
                             f"a different maneuver ({_spec_difference(stored_spec, given_spec)}); a warm start "
                             f"needs the same maneuver specification")
        start_params = np.array(source.current_params, dtype=float)
        if not maneuver.is_valid(start_params):
            raise ValueError(f"--from-session {source_id}: its learned parameters violate the maneuver's bounds")
        warm_from = source_id
    result = _design_from_args(args, config, maneuver)
    if not result.converged:
        raise CommandFailed(f"design failed, nothing to learn: {result.message}")
    rule_table = _rule_table(args)
    rule = _rule_from_table(rule_table, result, "--rule", maneuver=maneuver, config=config)
    plant = _build_plant(plant_kind, plant_config, config, args.seed, f"--plant {plant_kind}")
    target = args.iterations if args.iterations is not None else 30
    start = result.p_nominal if start_params is None else start_params
    session_id = store.create_session(
        vehicle=_vehicle_table(config), plant_kind=plant_kind, plant_config=plant_config, maneuver=maneuver,
        design=result, seed=args.seed, rule=rule_table, target_iterations=target,
        start_params=start, warm_start_from=warm_from, command=getattr(args, "argv", ()),
    )
    return _LearnRun(session_id, db, maneuver, result, config, plant, args.seed, rule, start, 0, 0, 0, target,
                     resumed=False, exact=True)


def _resumed_run(store, args, db: str) -> _LearnRun:
    from .design import Design
    from .maneuvers.registry import from_spec

    session_id = store.resolve_session(args.resume)
    rec = store.session(session_id)
    where = f"{db}: session {session_id}"
    mrec = store.maneuver(rec.maneuver_id)
    maneuver = from_spec(mrec.spec, source=f"{where} maneuver")
    drec = store.design(rec.design_id)
    prec = store.plant(rec.plant_id)
    model_config = _vehicle_from_table(store.vehicle(drec.vehicle_id).config, f"{where} design vehicle")
    plant_vehicle = _vehicle_from_table(store.vehicle(prec.vehicle_id).config, f"{where} plant vehicle")
    if args.maneuver is not None:
        _check_same_session(args, session_id, rec, mrec.spec, drec, prec, plant_vehicle)
    target = args.iterations if args.iterations is not None else rec.target_iterations
    # a session stopped after its last iteration but before it was closed just gets closed
    if target <= rec.n_measured and (rec.state == "completed" or target < rec.n_measured):
        raise ValueError(f"--resume {session_id}: session {session_id} already has {rec.n_measured} of "
                         f"{rec.target_iterations} measured iterations ({rec.display_state}); pass "
                         f"--iterations N with N > {rec.n_measured} to learn more")
    design = Design(
        maneuver=maneuver, p_guess=drec.p_guess, p_nominal=drec.p_nominal, residual=drec.residual,
        residual_norm=drec.residual_norm, converged=drec.converged, status=drec.status, message=drec.message,
        jacobian=drec.jacobian, correction=drec.correction, correction_kind=drec.correction_kind,
        singular_values=drec.singular_values, condition_number=drec.condition_number, rank=drec.rank,
        duration_s=drec.duration_s, compute_s=drec.compute_s, evaluations=drec.evaluations,
    )
    rule = _rule_from_table(rec.rule, design, f"{where} rule", maneuver=maneuver, config=model_config)
    if rec.rule.get("name") != "paper":
        _replay(rule, store.iterations(session_id), f"{where} rule")
    plant = _build_plant(prec.kind, prec.config, plant_vehicle, rec.seed, f"{where} plant")
    last = store.last_iteration(session_id)
    exact = True
    if last is not None and hasattr(plant, "set_state"):
        if last.plant_state is None:
            exact = False
        else:
            try:
                plant.set_state(last.plant_state)
            except ValueError as exc:
                raise ConfigError(f"{where}: stored plant state: {exc}") from None
    elif last is not None and prec.kind != "nominal":
        exact = False  # a plant without get_state/set_state continues from a fresh random state
    if not maneuver.is_valid(rec.current_params):
        raise ConfigError(f"{where}: stored parameters violate the maneuver's bounds")
    store.claim_session(session_id)
    if target != rec.target_iterations:
        store.set_target(session_id, target)
    return _LearnRun(session_id, db, maneuver, design, model_config, plant, rec.seed, rule, rec.current_params,
                     rec.last_correction, rec.last_index, rec.n_measured, target, resumed=True, exact=exact)


def _check_same_session(args, session_id: int, rec, stored_spec, drec, prec, plant_vehicle) -> None:
    """With --resume, a full command line must describe the stored session."""
    from .vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    given_spec = json.loads(json.dumps(_maneuver_from_args(args, config).spec()))
    differences = []
    if json.dumps(stored_spec, sort_keys=True) != json.dumps(given_spec, sort_keys=True):
        differences.append(f"maneuver: {_spec_difference(stored_spec, given_spec)}")
    kind, table = _plant_config(args)
    if kind != prec.kind:
        differences.append(f"--plant {kind} (stored: {prec.kind})")
    elif json.dumps(table, sort_keys=True) != json.dumps(prec.config, sort_keys=True):
        differences.append("--arena/--rotorpy settings differ from the stored plant")
    if _vehicle_table(config) != _vehicle_table(plant_vehicle):
        differences.append(f"--vehicle {args.vehicle} differs from the stored vehicle")
    if args.seed != rec.seed:
        differences.append(f"--seed {args.seed} (stored: {rec.seed})")
    if _rule_table(args) != rec.rule:
        differences.append(f"--rule {args.rule} --gamma {args.gamma} (stored: {rec.rule})")
    if args.correction != drec.correction_kind:
        differences.append(f"--correction {args.correction} (stored: {drec.correction_kind})")
    if differences:
        raise ValueError(f"--resume {session_id}: the command line describes another session: "
                         f"{'; '.join(differences)}; give only --resume {session_id} to use the stored settings")


def _replay(rule, iterations, source: str) -> None:
    """Bring a stateful rule to where it was: feed it the stored history, trial by trial.

    Rules are deterministic functions of their history (proposals and applied steps), so
    this reproduces their state exactly. Initial-state compensation needs the measured
    trajectories, which replay does not have.
    """
    import numpy as np

    if rule.name.endswith("+isc"):
        raise ConfigError(f"{source}: a '+isc' rule cannot be resumed exactly (it needs every trial's "
                          f"measured trajectory); start a new session with --from-session instead")
    for it in iterations:
        if it.status != "ok":
            continue
        rule.propose(it.correction, np.asarray(it.params), np.asarray(it.error), None)
        rule.observe(np.asarray(it.params), np.asarray(it.error), np.asarray(it.next_params) - np.asarray(it.params))


class _RecordingRule:
    """Wraps an update rule and remembers its last proposed step (to store p after the correction)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.name = inner.name
        self.last_step = None
        self.pending: tuple[int, Any] | None = None
        self.mismatch: Callable[[int, Any], None] | None = None

    def propose(self, i, params, error, trial):
        step, gamma = self.inner.propose(i, params, error, trial)
        self.last_step = step
        return step, gamma

    def observe(self, params, error, step) -> None:
        import numpy as np

        self.inner.observe(params, error, step)
        if self.pending is not None:  # learn() applies params + step: check what was stored
            index, stored = self.pending
            self.pending = None
            actual = params + step
            if not np.array_equal(actual, stored) and self.mismatch is not None:
                self.mismatch(index, actual)

    def state(self) -> dict[str, Any]:
        return self.inner.state()


class _Interrupts:
    """SIGINT/SIGTERM while learning: the first lets the trial in flight finish, then stops; a second aborts it."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self._critical = 0
        self._pending = False
        self._previous: dict[int, Any] = {}

    def install(self) -> None:
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handle)

    def restore(self, *, ignore: bool = False) -> None:
        """Put the previous handlers back, or with ``ignore`` ignore further signals (the process is ending)."""
        import signal

        for sig, handler in self._previous.items():
            signal.signal(sig, signal.SIG_IGN if ignore else handler)
        self._previous.clear()

    def _handle(self, signum: int, frame: Any) -> None:
        import os

        if self.signum is None:
            self.signum = signum
            os.write(2, b"aerobat: stopping after the trial in flight (interrupt again to abort it)\n")
            return
        if self._critical:
            self._pending = True
            return
        raise KeyboardInterrupt

    def requested(self) -> bool:
        return self.signum is not None

    @contextlib.contextmanager
    def critical(self) -> Iterator[None]:
        """A store commit: a second interrupt waits until it is done."""
        self._critical += 1
        try:
            yield
        finally:
            self._critical -= 1
            if self._pending and not self._critical:
                self._pending = False
                raise KeyboardInterrupt


def _warnings(message: str) -> list[str]:
    parts = (part.strip() for part in message.split(";"))
    return [part[len("warning:"):].strip() for part in parts if part.startswith("warning:")]


def _run_learning(store, run: _LearnRun, args: argparse.Namespace) -> int:
    import time

    import numpy as np
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from .learning import learn
    from .store import StoreError

    maneuver, plant, sid = run.maneuver, run.plant, run.session_id
    hint = f"aerobat learn --resume {sid} --db {run.db}"
    console = _console(args.json)

    def say(text: str) -> None:
        console.print(text, soft_wrap=True)  # one line per message, whatever the width
        console.file.flush()

    verb = "resumed" if run.resumed else "started"
    say(f"session {sid} {verb} in {run.db}: {maneuver.name} on {getattr(plant, 'name', type(plant).__name__)} "
        f"(seed {run.seed}), {run.measured} of {run.target} measured iterations done")
    if not run.exact:
        say(f"  note: the {getattr(plant, 'name', 'plant')} plant's state was not stored; resumed trials will "
            f"not repeat an uninterrupted run exactly")
    pos_idx = [k for k, e in enumerate(maneuver.errors) if e.unit == "m"]
    recording = _RecordingRule(run.rule)
    recording.mismatch = lambda index, actual: store.replace_next_params(sid, index, actual)
    interrupts = _Interrupts()
    warnings: list[str] = []
    get_state = getattr(plant, "get_state", None)
    with Progress(TextColumn("[bold]learning[/bold] {task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=True) as progress:
        task = progress.add_task(maneuver.name, total=run.target, completed=run.measured)

        def on_iteration(it) -> None:
            ok = it.status == "ok"
            next_params = it.params + it.scale * recording.last_step if ok else it.params
            trial = it.trial
            with interrupts.critical():
                store.append_iteration(
                    sid, index=it.index, correction=it.correction, status=it.status, params=it.params,
                    next_params=next_params, error=it.error, gamma=it.gamma, scale=it.scale, message=it.message,
                    final_state=None if trial is None else trial.final_state,
                    start_state=None if trial is None else trial.start_state,
                    times_s=None if trial is None else trial.times_s, states=None if trial is None else trial.states,
                    plant_state=get_state() if get_state is not None else None,
                    info=None if trial is None else trial.info,
                )
            recording.pending = (it.index, next_params) if ok else None
            # printed only once committed: every line is a stored iteration
            if ok:
                progress.advance(task)
                pos = float(np.linalg.norm(it.error[pos_idx])) if pos_idx else float("nan")
                say(f"  {it.index:3d}  ok          position error {pos:7.3f} m  γ={it.gamma:.2f}"
                    f"  scale={it.scale:.2f}")
            else:
                say(f"  {it.index:3d}  {it.status:10s}  {it.message}")
            for warning in _warnings(it.message):
                warnings.append(f"iteration {it.index}: {warning}")
                say(f"  warning: {warning}")

        interrupts.install()
        started = time.perf_counter()
        try:
            session = learn(maneuver, run.design, plant, iterations=run.target - run.measured, rule=recording,
                            start_params=run.start_params, start_correction=run.start_correction,
                            start_index=run.start_index, on_iteration=on_iteration,
                            should_stop=interrupts.requested)
            state = session.status if session.status in ("completed", "interrupted", "crashed", "aborted",
                                                         "failed") else "failed"
            message = session.message
        except KeyboardInterrupt:
            state, message = "interrupted", "interrupted: the trial in flight was abandoned"
            interrupts.signum = interrupts.signum or 2
        except StoreError as exc:
            with contextlib.suppress(StoreError):
                store.finish_session(sid, "failed", f"could not store an iteration: {exc}")
            raise CommandFailed(f"{exc}; session {sid} keeps every iteration stored before this one: "
                                f"resume with `{hint}` once fixed") from None
        except BaseException as exc:
            with contextlib.suppress(StoreError):
                store.finish_session(sid, "failed", f"{type(exc).__name__}: {exc}")
            raise
        finally:
            # once stopped by a signal, the program only closes the session and exits: a repeated
            # Ctrl-C must not kill it by signal while the interpreter shuts down (in-process callers,
            # e.g. tests, get their handlers back)
            interrupts.restore(ignore=interrupts.requested() and getattr(args, "standalone", False))
    wall_s = time.perf_counter() - started
    summary = store.session(sid)
    if state == "interrupted" and summary.n_measured >= run.target:
        state = "completed"
    if state == "completed":
        fresh = summary.n_measured - run.measured
        message = f"{summary.n_measured} measured iterations" + (f" ({fresh} after resuming)" if run.resumed else "")
    store.finish_session(sid, state, message)
    if state == "interrupted":
        signum = interrupts.signum or 2
        print(f"aerobat: interrupted: session {sid} stopped after iteration {summary.last_index} "
              f"({summary.n_measured} of {run.target} measured iterations stored); resume with: {hint}",
              file=sys.stderr, flush=True)
        return 128 + signum
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = _session_json(store, sid, run.db)
    data["wall_s"] = wall_s  # this invocation's learning time
    (out / "session.json").write_text(json.dumps(data, indent=1))
    notes = _session_figures(store, sid, out)
    if args.json:
        print(json.dumps({k: data[k] for k in ("error_names", "parameter_names", "iterations", "final_params",
                                                "status", "message", "plant", "session_id", "db")}))
    else:
        _print_stored_session(store, sid, iterations=True)
        for warning in warnings:
            console.print(f"warning: {warning}")
        for note in notes:
            console.print(note)
        console.print(f"figures and session.json in {out}/")
    if state != "completed":
        raise CommandFailed(f"{message}; session {sid} is stored: resume with `{hint}`")
    return EXIT_OK


# ------------------------------------------------------------ stored sessions


def _finite_or_none(values) -> list[float | None]:
    import math

    return [float(v) if math.isfinite(v) else None for v in values]


def _session_json(store, session_id: int, db: str, *, trajectories: bool = False, full: bool = False) -> dict:
    """The session as JSON: the keys of ``session.json`` (and, with ``full``, everything stored)."""
    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    prec = store.plant(rec.plant_id)
    iterations = []
    for it in store.iterations(session_id, trajectories=trajectories):
        entry = {
            "i": it.index, "correction": it.correction, "status": it.status,
            "params": it.params.tolist(), "next_params": it.next_params.tolist(),
            "error": _finite_or_none(it.error), "gamma": it.gamma, "scale": it.scale, "message": it.message,
        }
        if full:
            entry["final_state"] = None if it.final_state is None else _finite_or_none(it.final_state)
            entry["start_state"] = None if it.start_state is None else _finite_or_none(it.start_state)
            entry["recorded_at"] = it.recorded_at
            entry["info"] = it.info
        if trajectories:
            entry["trajectory"] = None if it.times_s is None else {
                "times_s": it.times_s.tolist(), "states": [_finite_or_none(row) for row in it.states]}
        iterations.append(entry)
    data: dict[str, Any] = {
        "session_id": session_id, "db": db,
        "maneuver": mrec.spec, "maneuver_name": mrec.name, "plant": prec.kind,
        "error_names": list(mrec.error_names), "error_units": list(mrec.error_units),
        "parameter_names": list(mrec.parameter_names), "parameter_units": list(mrec.parameter_units),
        "p_nominal": drec.p_nominal.tolist(), "start_params": rec.start_params.tolist(),
        "iterations": iterations, "final_params": rec.current_params.tolist(),
        "status": rec.display_state, "message": rec.message, "seed": rec.seed, "rule": rec.rule,
        "target_iterations": rec.target_iterations, "started_at": rec.started_at, "ended_at": rec.ended_at,
        "warm_start_from": rec.warm_start_from,
    }
    if full:
        data["plant_config"] = prec.config
        data["vehicle"] = store.vehicle(prec.vehicle_id).config
        data["command"] = list(rec.command)
        data["design"] = {
            "p_guess": drec.p_guess.tolist(), "p_nominal": drec.p_nominal.tolist(),
            "residual": _finite_or_none(drec.residual), "residual_norm": drec.residual_norm,
            "jacobian": [_finite_or_none(r) for r in drec.jacobian],
            "correction": [_finite_or_none(r) for r in drec.correction], "correction_kind": drec.correction_kind,
            "singular_values": _finite_or_none(drec.singular_values), "condition_number": drec.condition_number,
            "rank": drec.rank, "status": drec.status, "message": drec.message, "duration_s": drec.duration_s,
            "vehicle": store.vehicle(drec.vehicle_id).config,
        }
    return data


def _session_figures(store, session_id: int, out: Path) -> list[str]:
    """learning.png and side_views.png from stored data alone; notes on what could not be drawn."""
    from .maneuvers.registry import from_spec
    from .plotting import plot_learning, plot_side_views
    from .simulate import simulate

    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    notes = []
    panels = []
    target = mrec.spec.get("target_yz", (0.0, 0.0))
    try:
        maneuver = from_spec(mrec.spec, source=f"session {session_id} maneuver")
        config = _vehicle_from_table(store.vehicle(drec.vehicle_id).config, f"session {session_id} design vehicle")
        nominal = simulate(maneuver.program(drec.p_nominal), config)
        panels.append(("nominal (model)", nominal.times_s, nominal.states))
        target = getattr(maneuver, "target_yz", target)
    except ConfigError as exc:
        notes.append(f"note: nominal trajectory not drawn: {exc}")
    records = store.iterations(session_id)
    measured = [it.index for it in records if it.status == "ok" and it.trajectory_rows > 0]
    if measured:
        loaded = store.iterations(session_id, trajectories=True, indices=[measured[0], measured[-1]])
        by_index = {it.index: it for it in loaded}
        first, last = by_index[measured[0]], by_index[measured[-1]]
        panels.append((f"first attempt (iteration {first.index})", first.times_s, first.states))
        panels.append((f"learned (iteration {last.index})", last.times_s, last.states))
    plane = "xz" if mrec.spec.get("axis") == "pitch" else "yz"
    if panels:
        plot_side_views(panels, out / "side_views.png", plane=plane, title=mrec.name, target=tuple(target))
    if records:
        iterations = [{"i": it.index, "status": it.status, "params": it.params.tolist(),
                       "error": _finite_or_none(it.error)} for it in records]
        plot_learning(iterations, mrec.error_names, mrec.error_units, mrec.parameter_names, mrec.parameter_units,
                      out / "learning.png", title=f"{mrec.name} on {rec.plant_kind}")
    else:
        notes.append(f"note: session {session_id} has no iterations: learning.png not drawn")
    return notes


def _print_stored_session(store, session_id: int, *, iterations: bool, header: bool = False) -> None:
    import numpy as np
    from rich.table import Table

    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    console = _console(False)
    if header:
        prec = store.plant(rec.plant_id)
        lines = [
            f"session {rec.id}: {mrec.name} on {prec.kind} (seed {rec.seed}) — {rec.display_state}",
            f"  message:    {rec.message}",
            f"  started:    {rec.started_at}   updated: {rec.updated_at}   ended: {rec.ended_at or '—'}",
            f"  iterations: {rec.n_measured} measured of {rec.target_iterations} ({rec.n_records} trials, "
            f"last index {rec.last_index}, {rec.last_correction} corrections)",
            f"  rule:       {rec.rule.get('name')} with schedule {rec.rule.get('schedule')}",
            f"  design:     {drec.status}, residual {drec.residual_norm:.3g}, correction {drec.correction_kind}, "
            f"condition number {drec.condition_number:.3g}",
        ]
        if rec.warm_start_from is not None:
            lines.append(f"  warm start: from session {rec.warm_start_from}")
        if rec.last_position_error_m is not None:
            lines.append(f"  last position error: {rec.last_position_error_m:.4f} m")
        if rec.command:
            lines.append(f"  command:    aerobat {' '.join(rec.command)}")
        for line in lines:
            console.print(line)
    if iterations:
        table = Table(title=f"{mrec.name} on {rec.plant_kind}: {rec.display_state}")
        table.add_column("i", justify="right")
        table.add_column("status")
        table.add_column("γ", justify="right")
        table.add_column("scale", justify="right")
        for name, unit in zip(mrec.error_names, mrec.error_units, strict=True):
            table.add_column(f"{name} [{'°' if unit == 'rad' else unit}]", justify="right")
        for it in store.iterations(session_id):
            cells = [
                f"{np.degrees(v):+.2f}" if unit == "rad" else f"{v:+.3f}"
                for unit, v in zip(mrec.error_units, it.error, strict=True)
            ] if it.status == "ok" else ["—"] * len(mrec.error_names)
            table.add_row(str(it.index), it.status, f"{it.gamma:.2f}", f"{it.scale:.2f}", *cells)
        console.print(table)
    names = mrec.parameter_names
    console.print("p⁰:      " + "  ".join(f"{n}={v:.4g}" for n, v in zip(names, drec.p_nominal, strict=True)))
    console.print("learned: " + "  ".join(f"{n}={v:.4g}" for n, v in zip(names, rec.current_params, strict=True)))
    console.print(f"{rec.message}")


def _open_existing(args: argparse.Namespace):
    from .store import Store, default_path

    return Store(default_path() if args.db is None else args.db, create=False)


def _cmd_sessions(args: argparse.Namespace) -> int:
    if args.limit is not None and args.limit < 1:
        raise ValueError(f"--limit {args.limit}: expected a positive number of sessions")
    with _open_existing(args) as store:
        rows = store.list_sessions(limit=args.limit, newest_first=args.limit is not None)
        if args.limit is not None:
            rows.reverse()
        if args.json:
            print(json.dumps([{
                "id": r.id, "maneuver": r.maneuver_name, "plant": r.plant_kind, "seed": r.seed,
                "iterations": r.n_measured, "trials": r.n_records, "target": r.target_iterations,
                "last_position_error_m": r.last_position_error_m, "state": r.display_state,
                "started_at": r.started_at, "updated_at": r.updated_at} for r in rows]))
            return EXIT_OK
        if not rows:
            print(f"no sessions in {store.path}")
            return EXIT_OK
        header = ("id", "maneuver", "plant", "seed", "iterations", "trials", "last error [m]", "state", "started (UTC)")
        table = [header] + [(
            str(r.id), r.maneuver_name, r.plant_kind, "—" if r.seed is None else str(r.seed),
            f"{r.n_measured}/{r.target_iterations}", str(r.n_records),
            "—" if r.last_position_error_m is None else f"{r.last_position_error_m:.4f}",
            r.display_state, r.started_at[:19].replace("T", " ")) for r in rows]
        widths = [max(len(row[k]) for row in table) for k in range(len(header))]
        right = {0, 3, 4, 5, 6}
        lines = ["  ".join(cell.rjust(w) if k in right else cell.ljust(w)
                           for k, (cell, w) in enumerate(zip(row, widths, strict=True))).rstrip() for row in table]
        lines.insert(1, "  ".join("-" * w for w in widths))
        sys.stdout.write("\n".join(lines) + "\n")
    return EXIT_OK


def _cmd_show(args: argparse.Namespace) -> int:
    with _open_existing(args) as store:
        session_id = store.resolve_session(args.session)
        if args.json:
            print(json.dumps(_session_json(store, session_id, str(store.path), full=True)))
        else:
            _print_stored_session(store, session_id, iterations=True, header=True)
    return EXIT_OK


def _cmd_plot(args: argparse.Namespace) -> int:
    with _open_existing(args) as store:
        session_id = store.resolve_session(args.session)
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        notes = _session_figures(store, session_id, out)
    for note in notes:
        print(note)
    print(f"figures of session {session_id} in {out}/")
    return EXIT_OK


def _cmd_export(args: argparse.Namespace) -> int:
    import csv
    import io

    with _open_existing(args) as store:
        session_id = store.resolve_session(args.session)
        if args.format == "json":
            text = json.dumps(_session_json(store, session_id, str(store.path), trajectories=args.trajectories,
                                            full=True), indent=1) + "\n"
        else:
            if args.trajectories:
                raise ValueError("--trajectories: only with --format json")
            rec = store.session(session_id)
            mrec = store.maneuver(rec.maneuver_id)
            buffer = io.StringIO()
            writer = csv.writer(buffer, lineterminator="\n")
            writer.writerow(["session", "i", "correction", "status", "gamma", "scale",
                             *(f"{n} [{u}]" for n, u in zip(mrec.parameter_names, mrec.parameter_units, strict=True)),
                             *(f"next {n} [{u}]" for n, u in zip(mrec.parameter_names, mrec.parameter_units,
                                                                  strict=True)),
                             *(f"error {n} [{u}]" for n, u in zip(mrec.error_names, mrec.error_units, strict=True)),
                             "message", "recorded_at"])
            for it in store.iterations(session_id):
                writer.writerow([session_id, it.index, it.correction, it.status, repr(it.gamma), repr(it.scale),
                                 *(repr(float(v)) for v in it.params), *(repr(float(v)) for v in it.next_params),
                                 *("" if v is None else repr(v) for v in _finite_or_none(it.error)),
                                 it.message, it.recorded_at])
            text = buffer.getvalue()
    if args.output:
        Path(args.output).write_text(text)
        print(f"session {session_id} written to {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return EXIT_OK


# ------------------------------------------------------------------ fly


def _cmd_fly(args: argparse.Namespace) -> int:
    from .program import load_program
    from .simulate import final_state_summary
    from .vehicle import vehicle_from_name_or_file

    if args.trials < 1 or args.trials > 100000:
        raise ValueError(f"--trials {args.trials}: allowed 1 … 100000")
    program = load_program(args.program)
    config = vehicle_from_name_or_file(args.vehicle)
    plant = _plant_from_args(args, config)
    trials = []
    for k in range(args.trials):
        trial = plant.fly(program)
        entry = {"status": trial.status, "message": trial.message}
        entry.update(final_state_summary(trial.final_state, program.duration_s) if trial.ok else
                     {"final_state": None})
        trials.append(entry)
        if not args.json:
            _print_trial(k + 1, entry)
        if args.plot and k == 0 and trial.states.shape[0]:
            from .plotting import plot_side_views

            plot_side_views([("trial 1", trial.times_s, trial.states)], args.plot, title=str(args.program))
    if args.json:
        print(json.dumps({"trials": trials}))
    return EXIT_OK


def _print_trial(k: int, entry: dict[str, Any]) -> None:
    import math

    if entry["final_state"] is None:
        print(f"trial {k}: {entry['status']}: {entry['message']}")
        return
    fs = entry["final_state"]
    pos = ", ".join(f"{v:+.3f}" for v in fs["position_m"])
    vel = ", ".join(f"{v:+.3f}" for v in fs["velocity_m_s"])
    ang = ", ".join(f"{math.degrees(v):+.1f}" for v in fs["rotation_angle_rad"])
    print(f"trial {k}: ok  position [{pos}] m  velocity [{vel}] m/s  rotation [{ang}] °")


def _add_flip_options(p: argparse.ArgumentParser, *, optional: bool = False) -> None:
    if optional:
        p.add_argument("maneuver", nargs="?", choices=("flip", "translation"),
                       help="maneuver family (omit with --resume to use the stored session's)")
    else:
        p.add_argument("maneuver", choices=("flip", "translation"), help="maneuver family")
    p.add_argument("--flips", type=int, default=3, help="number of flips c_N (flip)")
    p.add_argument("--max-rate-deg-s", type=float, default=1800.0, help="coast rate c_pmax [deg/s] (flip)")
    p.add_argument("--dims", type=int, choices=(2, 3), default=3, help="2D (5 parameters) or 3D (9)")
    p.add_argument("--axis", choices=("roll", "pitch"), default="roll")
    p.add_argument("--coast", choices=("min", "max"), default="min", help="coast collective β̲ or β̄")
    p.add_argument("--ramp-s", type=float, default=0.1, help="thrust ramp-down duration [s]")
    p.add_argument("--to", default="5,5", help="target Y,Z [m] (translation)")
    p.add_argument("--final-angle-rad", type=float, default=0.0, help="final roll angle (translation)")
    p.add_argument("--vehicle", default="hummingbird", help="preset name or vehicle TOML file")
    p.add_argument("--correction", choices=("tsvd", "inverse", "damped"), default="tsvd",
                   help="right inverse used for C (default tsvd, see docs/results.md)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _add_plant_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", choices=("nominal", "arena", "rotorpy"), default="arena")
    p.add_argument("--arena", metavar="FILE.toml", help="arena configuration")
    p.add_argument("--rotorpy", metavar="FILE.toml", help="RotorPy parameter overrides")
    p.add_argument("--seed", type=int, default=0, help="seed of the plant's random generator")


def _session_ref(text: str) -> str:
    """A session reference: a positive id or ``last``."""
    if text.strip().lower() == "last" or (text.strip().isdigit() and int(text) >= 1):
        return text.strip().lower()
    raise argparse.ArgumentTypeError(f"{text!r}: expected a session id (1, 2, …) or 'last'")


def _add_db_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--db", metavar="PATH", help="experiment database (default: $AEROBAT_DB or ./aerobat.sqlite)")


# ----------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="aerobat", description="Design and learn fast open-loop quadrocopter maneuvers.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    sim = sub.add_parser("simulate", help="play a program on the nominal model")
    sim.add_argument("program", help="program TOML file")
    sim.add_argument("--vehicle", default="hummingbird", help="preset name or vehicle TOML file")
    sim.add_argument("--mode", choices=("continuous", "sampled"), default="continuous",
                     help="continuous-time model or 800 Hz onboard zero-order hold")
    sim.add_argument("--plot", metavar="FILE.png", help="write a figure")
    sim.add_argument("--json", action="store_true", help="print one JSON object")
    sim.set_defaults(func=_cmd_simulate)

    des = sub.add_parser("design", help="nominal design: p⁰, J, C")
    _add_flip_options(des)
    des.set_defaults(func=_cmd_design)

    lrn = sub.add_parser("learn", help="design, then learn on a plant (every iteration goes to the database)")
    _add_flip_options(lrn, optional=True)
    _add_plant_options(lrn)
    lrn.add_argument("--iterations", type=int, default=None,
                     help="measured iterations (default 30; with --resume the stored target)")
    lrn.add_argument("--gamma", default="paper", help="'paper' (max(1/i, 0.1)) or a constant in (0, 1]")
    lrn.add_argument("--rule", default="paper",
                     help="update rule: paper, tsvd, damped, kalman, broyden, or <rule>+isc (docs/method.md)")
    lrn.add_argument("--out", default="out/learn", help="directory for figures and session.json")
    lrn.add_argument("--resume", metavar="SESSION", type=_session_ref,
                     help="continue a stored session (id or 'last') with its parameters, counters and plant state")
    lrn.add_argument("--from-session", metavar="SESSION", type=_session_ref,
                     help="start a new session from another session's learned parameters (same maneuver)")
    lrn.add_argument("--fsync", action="store_true",
                     help="make every commit survive power loss too (an fsync per iteration)")
    _add_db_option(lrn)
    lrn.set_defaults(func=_cmd_learn)

    ses = sub.add_parser("sessions", help="list the stored learning sessions")
    _add_db_option(ses)
    ses.add_argument("--limit", type=int, help="only the newest N sessions")
    ses.add_argument("--json", action="store_true", help="print one JSON array")
    ses.set_defaults(func=_cmd_sessions)

    show = sub.add_parser("show", help="a stored session: summary and per-iteration table")
    show.add_argument("session", type=_session_ref, help="session id or 'last'")
    _add_db_option(show)
    show.add_argument("--json", action="store_true", help="print everything stored (no trajectories) as JSON")
    show.set_defaults(func=_cmd_show)

    plot = sub.add_parser("plot", help="learning figures of a stored session, from stored data alone")
    plot.add_argument("session", type=_session_ref, help="session id or 'last'")
    plot.add_argument("--out", default="out/plot", metavar="DIR", help="directory for learning.png, side_views.png")
    _add_db_option(plot)
    plot.set_defaults(func=_cmd_plot)

    export = sub.add_parser("export", help="a stored session as CSV (one row per iteration) or JSON")
    export.add_argument("session", type=_session_ref, help="session id or 'last'")
    export.add_argument("--format", choices=("csv", "json"), default="csv")
    export.add_argument("--output", metavar="FILE", help="write to FILE instead of standard output")
    export.add_argument("--trajectories", action="store_true", help="include measured trajectories (json)")
    _add_db_option(export)
    export.set_defaults(func=_cmd_export)

    fly = sub.add_parser("fly", help="fly a program on a plant")
    fly.add_argument("program", help="program TOML file")
    fly.add_argument("--vehicle", default="hummingbird")
    _add_plant_options(fly)
    fly.add_argument("--trials", type=int, default=1)
    fly.add_argument("--json", action="store_true")
    fly.add_argument("--plot", metavar="FILE.png")
    fly.set_defaults(func=_cmd_fly)

    from . import cli_benchmark, cli_study

    cli_benchmark.register(sub)
    cli_study.register(sub)
    for register in _EXTRA_COMMANDS:
        register(sub)
    return parser


# Later modules register their commands here (kept in one list so `aerobat --help` shows all).
_EXTRA_COMMANDS: list[Callable[[Any], None]] = []


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split("\n"))


def main(argv: Sequence[str] | None = None) -> int:
    from .store import StoreError

    parser = build_parser()
    standalone = argv is None  # the installed command, not a caller passing arguments
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.argv = argv
    args.standalone = standalone
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("aerobat: interrupted", file=sys.stderr)
        return 130
    except StoreError as exc:
        if args.debug:
            raise
        label = "error" if exc.exit_code == EXIT_USAGE else "failed"
        print(f"aerobat: {label}: {_one_line(exc)}", file=sys.stderr)
        return exc.exit_code
    except (ConfigError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError, OSError) as exc:
        if args.debug:
            raise
        print(f"aerobat: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except CommandFailed as exc:
        if args.debug:
            raise
        print(f"aerobat: failed: {_one_line(exc)}", file=sys.stderr)
        return EXIT_FAILED
    except Exception as exc:  # a bug: still one line (--debug shows the traceback)
        if args.debug:
            raise
        print(f"aerobat: failed: internal error: {type(exc).__name__}: {_one_line(exc)} (--debug shows a traceback)",
              file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
