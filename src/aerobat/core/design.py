"""Nominal design (Fig. 3, Sect. 5): p⁰ with Φ(p⁰) = x*, the Jacobian J and the correction C.

Generic over maneuvers and models: a model only has to map a batch of
programs to final states (the :class:`FinalStateModel` protocol).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, fields
from enum import StrEnum
from typing import Any, Protocol

import numpy as np

from aerobat.config import as_float_array, check_type, short_repr
from aerobat.core.bounds import Integer, Interval, OneOf, bounded, validate
from aerobat.core.codec import Form, decode, encode
from aerobat.core.correction import CorrectionKind, correction_matrix, svd_info
from aerobat.core.maneuver import Maneuver, batch_errors, bounds_arrays, check_maneuver, error_scales, parameter_scales
from aerobat.errors import ConfigError, DesignFailed

__all__ = ["Design", "DesignFailed", "DesignStatus", "FinalStateModel", "design", "finite_difference_jacobian"]


class FinalStateModel(Protocol):
    """A model that maps a batch of programs (and optional initial states) to final states."""

    def final_states(self, programs: Sequence[Any], initial_states: np.ndarray | None = None) -> np.ndarray: ...


class DesignStatus(StrEnum):
    """How a nominal design ended."""

    CONVERGED = "converged"
    NOT_CONVERGED = "not_converged"
    RANK_DEFICIENT = "rank_deficient"

    @property
    def meaning(self) -> str:
        """One sentence on what this status means for the design's user."""
        return {
            DesignStatus.CONVERGED: "p⁰ reaches the target on the model and J has full row rank",
            DesignStatus.NOT_CONVERGED: "no parameters within the bounds reach the target on the model",
            DesignStatus.RANK_DEFICIENT: "p⁰ reaches the target but some errors cannot be corrected (J rank-deficient)",
        }[self]


@dataclass(frozen=True)
class Design:
    """Result of the nominal design.

    Attributes
    ----------
    maneuver : the maneuver designed.
    p_guess, p_nominal : (n_par,) initial guess p^g and solution p⁰.
    residual : (n_err,) e(p⁰) on the nominal model; ``residual_norm`` its 2-norm (SI units mixed).
    converged : True if the residual norm is below the tolerance and J has full row rank.
    status : the outcome (:class:`DesignStatus`); ``message`` says why in words.
    jacobian : (n_err, n_par) J = ∂e/∂p at p⁰ (central differences).
    correction : (n_par, n_err) C, a right inverse of J.
    correction_kind : how C was computed.
    singular_values, condition_number, rank : of J in scaled coordinates.
    duration_s : the nominal program's duration, ramps included.
    compute_s : wall time of the design.
    """

    maneuver: Maneuver
    p_guess: np.ndarray
    p_nominal: np.ndarray
    residual: np.ndarray
    residual_norm: float
    converged: bool
    status: DesignStatus
    message: str
    jacobian: np.ndarray
    correction: np.ndarray
    correction_kind: str
    singular_values: np.ndarray
    condition_number: float
    rank: int
    duration_s: float
    compute_s: float
    evaluations: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", DesignStatus(self.status))

    def __repr__(self) -> str:
        return (f"Design({self.maneuver.name!r}, status={self.status.value!r}, "
                f"residual_norm={self.residual_norm:.3g}, condition_number={self.condition_number:.3g})")

    def summary(self) -> str:
        """A few lines a person reads: parameters with meaning and unit, outcome, conditioning."""
        m = self.maneuver
        width = max(len(p.description) for p in m.parameters) if m.parameters else 0
        lines = [f"design of {m.name}: {self.status.value} — {self.message.removeprefix(self.status.value + ': ')}"]
        lines.append(f"  {'':4s} {'meaning':{width}s}  {'guess p^g':>11s}  {'nominal p⁰':>11s}  unit")
        for spec, g, p in zip(m.parameters, self.p_guess, self.p_nominal, strict=True):
            lines.append(f"  {spec.name:4s} {spec.description:{width}s}  {g:11.5g}  {p:11.5g}  {spec.unit}")
        lines.append(f"  residual norm {self.residual_norm:.3g}; duration {self.duration_s:.4f} s (ramps included)")
        lines.append(f"  condition number of the scaled J {self.condition_number:.3g} (rank {self.rank}); "
                     f"correction {self.correction_kind}; {self.evaluations} simulations in "
                     f"{self.compute_s * 1e3:.0f} ms")
        return "\n".join(lines)

    @classmethod
    def from_json_dict(cls, maneuver: Maneuver, table: dict[str, Any]) -> Design:
        """The design that :meth:`to_json_dict` wrote, for ``maneuver`` (arrays exact; the core's codec)."""
        try:
            return decode(cls, table, form=Form.JSON, maneuver=maneuver)  # type: ignore[no-any-return]
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"design table: {type(exc).__name__}: {exc}") from None

    def to_json_dict(self) -> dict[str, Any]:
        """The design as plain JSON types (arrays as lists; the core's codec), with its maneuver's spec and names."""
        m = self.maneuver
        return {"maneuver": m.spec(), "parameter_names": [p.name for p in m.parameters],
                "parameter_units": [p.unit for p in m.parameters], "error_names": [e.name for e in m.errors],
                **encode(self, (f.name for f in fields(self) if f.name != "maneuver"), form=Form.JSON)}


class _CountingModel:
    """Counts simulations (for the design report)."""

    def __init__(self, model: FinalStateModel) -> None:
        self.model = model
        self.count = 0

    def final_states(self, programs: Sequence[Any], initial_states: np.ndarray | None = None) -> np.ndarray:
        self.count += len(programs)
        return self.model.final_states(programs, initial_states)


def _errors(maneuver: Maneuver, model: FinalStateModel, params: np.ndarray) -> np.ndarray:
    """(B, n_err) errors for a batch of parameter vectors (B, n_par): one model call."""
    programs = [maneuver.program(p) for p in params]
    return batch_errors(maneuver, model.final_states(programs))


class _Evaluations:
    """e(p) during one design: every batch is one model call, and no p is simulated twice.

    The simulations are deterministic, so a remembered e(p) is exactly what simulating p again
    would give; Newton's iterates, their Jacobians' centre points and the final J at p⁰ recur.
    """

    def __init__(self, maneuver: Maneuver, model: FinalStateModel, relative_step: float = 1e-3) -> None:
        self.maneuver = maneuver
        self.model = model
        self.relative_step = relative_step
        self.known: dict[bytes, np.ndarray] = {}

    def __call__(self, params: np.ndarray) -> np.ndarray:
        params = np.asarray(params, dtype=float)
        keys = [p.tobytes() for p in params]
        todo = {k: p for k, p in zip(keys, params, strict=True) if k not in self.known}
        if todo:
            errs = _errors(self.maneuver, self.model, np.array(list(todo.values())))
            self.known.update(zip(todo, errs, strict=True))
        return np.array([self.known[k] for k in keys])


def _difference_batch(maneuver: Maneuver, p: np.ndarray, relative_step: float) -> tuple[np.ndarray, np.ndarray]:
    """The 2·n + 1 parameter vectors of a central-difference J at ``p``, and the steps taken."""
    p = np.asarray(p, dtype=float)
    n = p.size
    lower, upper = bounds_arrays(maneuver.parameters)
    h = relative_step * parameter_scales(maneuver.parameters)
    plus = np.minimum(p + h, upper)
    minus = np.maximum(p - h, lower)
    batch = np.empty((2 * n + 1, n))
    batch[0] = p
    for i in range(n):
        batch[1 + i] = p
        batch[1 + i, i] = plus[i]
        batch[1 + n + i] = p
        batch[1 + n + i, i] = minus[i]
    return batch, plus - minus


def _jacobian_from(errs: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = steps.size
    # C order, as a design read back from the store has it: products with J (BLAS) round the same
    # way in a running session and in a resumed one
    J = np.ascontiguousarray((errs[1 : n + 1] - errs[n + 1 :]).T / steps[None, :])
    return J, errs[0]


def finite_difference_jacobian(
    maneuver: Maneuver, model: FinalStateModel, p: np.ndarray, *, relative_step: float = 1e-3
) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference J at ``p`` with steps ``relative_step`` × each parameter's scale.

    Steps are shrunk (one-sided if needed) to stay inside the parameter bounds.
    Returns (J, e(p)). All 2·n + 1 simulations run as one parallel batch.
    """
    batch, steps = _difference_batch(maneuver, p, relative_step)
    return _jacobian_from(_errors(maneuver, model, batch), steps)


def _forward_difference_batch(maneuver: Maneuver, p: np.ndarray, relative_step: float) -> tuple[np.ndarray, np.ndarray]:
    """The n + 1 parameter vectors of a one-sided J at ``p``, and the steps taken (up, or down at an upper bound)."""
    p = np.asarray(p, dtype=float)
    lower, upper = bounds_arrays(maneuver.parameters)
    h = relative_step * parameter_scales(maneuver.parameters)
    plus = np.minimum(p + h, upper)
    # a parameter at (or within half a step of) its upper bound steps down
    other = np.where(plus - p < 0.5 * h, np.maximum(p - h, lower), plus)
    batch = np.repeat(p[None, :], p.size + 1, axis=0)
    batch[1:][np.diag_indices(p.size)] = other
    return batch, other - p


def _jacobian(evaluate: _Evaluations, p: np.ndarray, *, central: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """:func:`finite_difference_jacobian` through the design's evaluations (one batch, nothing repeated).

    ``central=False``: forward differences, n + 1 simulations instead of 2·n + 1 (the coarse Newton pass,
    which needs the step's direction, not J to the last digits).
    """
    if central:
        batch, steps = _difference_batch(evaluate.maneuver, p, evaluate.relative_step)
        return _jacobian_from(evaluate(batch), steps)
    batch, steps = _forward_difference_batch(evaluate.maneuver, p, evaluate.relative_step)
    errs = evaluate(batch)
    return np.ascontiguousarray((errs[1:] - errs[0]).T / steps[None, :]), errs[0]


@dataclass(frozen=True, kw_only=True)
class _DesignArguments:
    """The numeric options of :func:`design`, with their bounds (the same defaults as its signature)."""

    correction: CorrectionKind = bounded("tsvd", OneOf(CorrectionKind))
    tolerance: float = bounded(1e-6, Interval(low=0.0, closed="neither", as_float=True))
    tsvd_rtol: float = bounded(1e-3, Interval(low=0.0, as_float=True))
    damping: float = bounded(1e-3, Interval(low=0.0, as_float=True))
    max_iterations: int = bounded(100, Integer(1, 1_000_000))
    relative_step: float = bounded(1e-3, Interval(low=0.0, high=1.0, closed="right", as_float=True))

    def __post_init__(self) -> None:
        validate(self)


def design(
    maneuver: Maneuver,
    model: FinalStateModel,
    *,
    p_guess: np.ndarray | None = None,
    tolerance: float = 1e-6,
    correction: CorrectionKind = "tsvd",
    tsvd_rtol: float = 1e-3,
    damping: float = 1e-3,
    max_iterations: int = 100,
    relative_step: float = 1e-3,
    raise_on_failure: bool = False,
) -> Design:
    """Find p⁰ with e(p⁰) = 0 on ``model`` from the guess, then J and C (Sect. 3 step 2).

    A bounded trust-region least-squares solve on scaled errors, with batched
    finite-difference Jacobians. The result says whether it converged and why
    not; with ``raise_on_failure`` a failure raises :class:`DesignFailed`. ``relative_step``: the
    Jacobian's central differences step this fraction of each parameter's scale (a model with fine
    structure in its response, such as a flight controller's discrete frames, asks for wider ones).
    """
    start = time.perf_counter()
    check_maneuver(maneuver)
    if not callable(getattr(model, "final_states", None)):
        raise ConfigError(f"model: expected a final-state model (e.g. NominalModel(config)), got "
                          f"{type(model).__name__} {short_repr(model)}")
    options = _DesignArguments(correction=correction, tolerance=tolerance, tsvd_rtol=tsvd_rtol, damping=damping,
                               max_iterations=max_iterations, relative_step=relative_step)
    tolerance, tsvd_rtol, damping = options.tolerance, options.tsvd_rtol, options.damping
    max_iterations = options.max_iterations
    check_type("raise_on_failure", raise_on_failure, (bool, np.bool_), "True or False")
    model = _CountingModel(model)
    guess = (np.array(maneuver.guess(), dtype=float) if p_guess is None
             else as_float_array("p_guess", p_guess, (len(maneuver.parameters),)))
    lower, upper = bounds_arrays(maneuver.parameters)
    p_scales = parameter_scales(maneuver.parameters)
    e_scales = error_scales(maneuver.errors)
    x0 = np.clip(guess, lower, upper)
    evaluate = _Evaluations(maneuver, model, options.relative_step)

    def residual(p: np.ndarray) -> np.ndarray:
        return evaluate(p[None, :])[0] / e_scales

    def jac(p: np.ndarray) -> np.ndarray:
        return _jacobian(evaluate, p)[0] / e_scales[:, None]

    status = DesignStatus.CONVERGED
    message = ""
    # Newton in two passes: first ignoring nearly unobservable directions (they send a full
    # Newton step wandering along a valley), then a polishing pass with all of them
    # (the coarse pass steers by forward differences, n + 1 simulations per Jacobian instead of 2·n + 1: the
    # 3D triple flip designs in 191 simulations instead of 262, p⁰ the same to 2e-10; the polish and the final
    # J, from which C comes, keep central differences)
    coarse = _newton(evaluate, x0, lower, upper, p_scales, e_scales, 1e5 * tolerance, rcond=1e-4,
                     max_iterations=15, central=False)[0]
    p0, solver_message, ok = _newton(evaluate, coarse, lower, upper, p_scales, e_scales, tolerance)
    if not ok:
        # Newton did not get there: a bounded trust-region solve finds the best reachable
        # parameters, so the failure message can say which limits are in the way
        from scipy.optimize import least_squares  # only here: importing it costs half a second

        try:
            result = least_squares(
                residual, x0, jac=jac, bounds=(lower, upper), x_scale=p_scales, method="trf",
                xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=max_iterations,
            )
            p0 = result.x
            solver_message = f"Newton failed ({solver_message}); trust region: {result.message}"
        except (ValueError, FloatingPointError) as exc:  # non-finite model output
            p0 = x0
            solver_message = f"solver aborted: {exc}"
    J, e0 = _jacobian(evaluate, p0)
    residual_norm = float(np.linalg.norm(e0))
    converged = bool(np.all(np.isfinite(e0)) and residual_norm < tolerance)
    pinned = _pinned(maneuver, p0, lower, upper)
    info = svd_info(J, p_scales, e_scales)
    n_err = len(maneuver.errors)
    if not converged:
        status = DesignStatus.NOT_CONVERGED
        message = (
            f"no parameters reach the target on the nominal model: residual norm {residual_norm:.3g} "
            f"> tolerance {tolerance:g} ({solver_message})"
        )
        worst = int(np.argmax(np.abs(e0) / e_scales)) if np.all(np.isfinite(e0)) else 0
        message += f"; largest error {maneuver.errors[worst].name} = {e0[worst]:+.4g} {maneuver.errors[worst].unit}"
        if pinned:
            # named limits first (the vehicle's envelope): they are what makes a maneuver infeasible
            pinned.sort(key=lambda limit: not limit[0])
            message += "; violated limits: " + "; ".join(text for _, text in pinned)
        hint = _failure_hint(maneuver, evaluate, x0)
        if hint:
            message += f"; hint: {hint}"
    elif info.rank < n_err:
        status = DesignStatus.RANK_DEFICIENT
        message = (
            f"the Jacobian has rank {info.rank} < {n_err} errors: some errors cannot be corrected "
            f"with these parameters (scaled singular values {np.array2string(info.singular_values, precision=3)})"
        )
    else:
        message = f"residual norm {residual_norm:.3g}; {solver_message}"
    usable = status is not DesignStatus.RANK_DEFICIENT and np.all(np.isfinite(J))
    C = (
        correction_matrix(J, p_scales, e_scales, kind=correction, tsvd_rtol=tsvd_rtol, damping=damping)
        if usable
        else np.full((J.shape[1], J.shape[0]), np.nan)
    )
    try:
        duration = float(maneuver.duration_s(p0))
    except ValueError:
        duration = math.nan
    result_design = Design(
        maneuver=maneuver,
        p_guess=guess,
        p_nominal=p0,
        residual=e0,
        residual_norm=residual_norm,
        converged=converged and status is DesignStatus.CONVERGED,
        status=status,
        message=message,
        jacobian=J,
        correction=C,
        correction_kind=correction,
        singular_values=info.singular_values,
        condition_number=info.condition_number,
        rank=info.rank,
        duration_s=duration,
        compute_s=time.perf_counter() - start,
        evaluations=model.count,
    )
    if raise_on_failure and not result_design.converged:
        raise DesignFailed(f"{maneuver.name}: design failed: {message}", result_design)
    return result_design


def _failure_hint(maneuver: Maneuver, evaluate: _Evaluations, guess: np.ndarray) -> str | None:
    """The maneuver's own reading of its error at the guess (optional ``failure_hint(params, error)``)."""
    hint = getattr(maneuver, "failure_hint", None)
    if not callable(hint):
        return None
    try:
        text = hint(guess, evaluate(guess[None, :])[0])
    except (ValueError, FloatingPointError, ConfigError):
        return None
    return text if isinstance(text, str) and text.strip() else None


def _newton(
    evaluate: _Evaluations,
    x0: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    p_scales: np.ndarray,
    e_scales: np.ndarray,
    tolerance: float,
    max_iterations: int = 25,
    max_scaled_step: float = 5.0,
    rcond: float = 1e-8,
    line_batch: int = 2,
    central: bool = True,
) -> tuple[np.ndarray, str, bool]:
    """Bounded Newton iteration in scaled coordinates with backtracking.

    A fresh finite-difference Jacobian whenever progress is slow, chord steps (reusing
    it) while the residual falls fast. The backtracking line search tries its step lengths
    1, ½, ¼, … ``line_batch`` at a time in one model call (they run in parallel) and takes
    the first that lowers the residual, as a one-at-a-time search would. ``central``: central
    differences for J, else forward ones. Returns (best p, message, converged).
    """
    x = x0.copy()
    try:
        J, e = _jacobian(evaluate, x, central=central)
    except ValueError as exc:
        return x, f"Jacobian not computable at the initial guess: {exc}", False
    if not np.all(np.isfinite(e)):
        return x, "non-finite final state at the initial guess", False
    for iteration in range(max_iterations):
        norm = float(np.linalg.norm(e))
        if norm < 0.01 * tolerance:
            return x, f"Newton converged in {iteration} iteration{'' if iteration == 1 else 's'}", True
        Js = (J / e_scales[:, None]) * p_scales[None, :]
        scaled_step = np.linalg.lstsq(Js, e / e_scales, rcond=rcond)[0]
        # active bounds: parameters at a bound that the step pushes further out are held fixed
        blocked = ((x <= lower + 1e-12) & (scaled_step > 0)) | ((x >= upper - 1e-12) & (scaled_step < 0))
        if blocked.any() and not blocked.all():
            free = ~blocked
            scaled_step = np.zeros_like(scaled_step)
            scaled_step[free] = np.linalg.lstsq(Js[:, free], e / e_scales, rcond=rcond)[0]
        longest = float(np.max(np.abs(scaled_step)))
        if longest > max_scaled_step:  # stay where the linear model means something
            scaled_step *= max_scaled_step / longest
        step = -p_scales * scaled_step
        accepted = _line_search(evaluate, x, step, e, lower, upper, e_scales, line_batch)
        if accepted is None:
            return x, (f"no descent after {iteration} Newton iteration{'' if iteration == 1 else 's'}, residual "
                        f"{norm:.3g}"), norm < tolerance
        t, candidate, e_new = accepted
        slow = np.linalg.norm(e_new) > 0.1 * norm
        x, e = candidate, e_new
        if slow or t < 1.0:  # otherwise a chord step: keep the Jacobian
            try:
                J, e = _jacobian(evaluate, x, central=central)
            except ValueError as exc:
                return x, f"Jacobian not computable near the iterate: {exc}", False
    norm = float(np.linalg.norm(e))
    return x, (f"Newton stopped after {max_iterations} iteration{'' if max_iterations == 1 else 's'}, "
               f"residual {norm:.3g}"), norm < tolerance


def _line_search(evaluate: _Evaluations, x: np.ndarray, step: np.ndarray, e: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, e_scales: np.ndarray, batch: int) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(t, x + t·step clipped, its errors) for the longest t in 1, ½, … ¼⁶ that lowers the scaled residual."""
    lengths = [0.5**k for k in range(7)]  # down to 1/64, as the one-at-a-time search went
    target = np.linalg.norm(e / e_scales)
    for first in range(0, len(lengths), batch):
        ts = lengths[first : first + batch]
        candidates = np.array([np.clip(x + t * step, lower, upper) for t in ts])
        try:
            errs = evaluate(candidates)
        except ValueError:  # a step left the maneuver's valid set (e.g. absurd commands): try them one by one
            errs = np.array([_or_nan(evaluate, c, e) for c in candidates])
        for t, candidate, e_new in zip(ts, candidates, errs, strict=True):
            if np.all(np.isfinite(e_new)) and np.linalg.norm(e_new / e_scales) < target:
                return t, candidate, e_new
    return None


def _or_nan(evaluate: _Evaluations, p: np.ndarray, like: np.ndarray) -> np.ndarray:
    try:
        return evaluate(p[None, :])[0]
    except ValueError:
        return np.full_like(like, np.nan)


def _pinned(maneuver: Maneuver, p: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> list[tuple[bool, str]]:
    """(has a named limit, description) of every parameter that sits on a bound."""
    out = []
    for spec, value, lo, hi in zip(maneuver.parameters, p, lower, upper, strict=True):
        # within 1e-4 of its scale: a bounded trust-region solve that stops on `ftol` leaves a pinned
        # parameter ~1e-5 scales inside its bound (the 1e-6 used before made the named reason depend
        # on the last bits of the model)
        side = spec.pinned(value)
        if not side:
            continue
        bound, limit = (spec.bound_names[0], lo) if side == "lower" else (spec.bound_names[1], hi)
        name = f" = {bound}" if bound else ""
        out.append((bool(bound), f"{spec.name} ({spec.description}) = {value:.4g} {spec.unit} at its {side} "
                                 f"limit {limit:.4g}{name}"))
    return out
