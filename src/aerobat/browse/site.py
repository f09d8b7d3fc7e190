"""The browser's pages: every page of a store as bytes, for the server and for a static export alike.

A :class:`Site` opens the store read-only (SQLite ``mode=ro``: it never writes the file) and
answers a relative path (``index.html``, ``session-3.html``, ``session-3/learning.png``…)
with its content type and bytes. Pages link to each other by relative paths, so the same
pages work served by :mod:`aerobat.browse.server` and written to a folder by :meth:`Site.export`.
Figures are drawn from stored data alone (:func:`aerobat.experiments.reports.session_figures`)
and cached per session state; the 3D replay is the one ``aerobat replay`` writes.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import tempfile
import threading
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import numpy as np

from aerobat.browse.catalog import job_summary, json_text, session_row, session_rows, study_rows
from aerobat.core.learning import IterationStatus, SessionStatus
from aerobat.core.registry import parameters_of
from aerobat.errors import ConfigError, SessionNotFound
from aerobat.fileio import check_output, check_output_folder, make_output_folder, write_output
from aerobat.store import Store
from aerobat.store.query import SessionQuery, SortKey
from aerobat.store.records import JobStatus

__all__ = ["MAX_COMPARED", "MAX_ID", "PAGE_ROWS", "NotFound", "Site", "session_query"]


class NotFound(SessionNotFound):
    """A page the store has nothing for (an unknown session, study, figure or path)."""


MAX_ID = 2**63 - 1
"""The largest id a store can hold (SQLite's largest integer): a page for a larger one does not exist."""
MAX_COMPARED = 50
"""The most sessions one comparison shows."""
PAGE_ROWS = 100
"""Sessions on one page of the sessions table."""
_FILTERS = {"maneuver": "maneuver", "plant": "plant", "vehicle": "vehicle", "feedback": "feedback", "rule": "rule",
            "status": "status", "tag": "tag", "q": "text", "from": "since", "to": "until"}
"""The table's query parameters and the :class:`~aerobat.store.query.SessionQuery` fields they set."""
_ON = ("1", "on", "true", "yes")

_N = "([0-9]+)"  # an id: ASCII digits only (a regular expression's \d also matches "١")
_PAGE = re.compile(
    rf"^(?:(index)(?:-{_N})?\.html|session-{_N}\.html|study-{_N}\.html|compare\.html|api/session-{_N}\.json"
    rf"|session-{_N}/(learning|side_views)\.png|session-{_N}/replay-([0-9]+|default)\.html"
    rf"|study-{_N}/([\w.-]+\.png)|compare/([0-9]+(?:-[0-9]+)+)\.png|assets/(plotly\.min\.js))$")


def _id(text: str, what: str) -> int:
    """The id a page names (digits); :class:`NotFound` for one no store can hold (not parsed: a 5,000-digit
    number would be refused by Python's integer conversion limit, and a 20-digit one by SQLite)."""
    if len(text) > len(str(MAX_ID)) or int(text) > MAX_ID:
        raise NotFound(f"no {what} {text[:20]}{'…' if len(text) > 20 else ''} (ids go up to {MAX_ID})")
    return int(text)


def _bad(name: str, value: str, expected: str) -> Any:
    shown = repr(value if len(value) <= 40 else value[:40] + "…")
    raise ConfigError(f"{name}={shown}: expected {expected}")


def session_query(params: Mapping[str, str], *, limit: int | None = None, offset: int = 0) -> SessionQuery:
    """The :class:`~aerobat.store.query.SessionQuery` of the sessions table's query parameters (``plant=arena``,
    ``q=text``, ``from=2026-01-01``, ``studies=1``, ``sort=error``, ``dir=desc``…); empty ones are no filter."""
    given = {k: v for k, v in params.items() if isinstance(v, str) and v.strip()}
    fields: dict[str, Any] = {_FILTERS[k]: v for k, v in given.items() if k in _FILTERS}
    if "study" in given:
        study = given["study"].strip()
        fields["study"] = _id(study, "study") if study.isascii() and study.isdigit() else \
            _bad("study", study, "a study id")
    fields["include_studies"] = given.get("studies", "").strip().lower() in _ON
    if "sort" in given:
        if given["sort"] not in tuple(SortKey):
            _bad("sort", given["sort"], "one of " + ", ".join(SortKey))
        fields["sort"] = SortKey(given["sort"])
    if given.get("dir", "asc") not in ("asc", "desc"):
        _bad("dir", given["dir"], "asc or desc")
    fields["descending"] = given.get("dir") == "desc"
    return SessionQuery(**fields, limit=limit, offset=offset)


def _index_link(params: Mapping[str, str], static: bool, **change: Any) -> str:
    """The link to another page or order of the sessions table (the server keeps the filters in the query)."""
    if static:
        page = int(change.get("page", 1))
        return "index.html" if page <= 1 else f"index-{page}.html"
    merged = {k: v for k, v in {**params, **{k: str(v) for k, v in change.items()}}.items() if v not in ("", None)}
    if merged.get("page") == "1":
        del merged["page"]
    return "index.html" + ("?" + urlencode(merged) if merged else "")


def _dtick(curves: Sequence[Mapping[str, Any]]) -> int:
    """A whole-number trial step giving at most about ten ticks (1, 2, 5, 10, 20, 50…)."""
    last = max([max(c["x"]) for c in curves if c["x"]] or [1])
    step = 1
    while last / step > 10:
        step = step * 5 // 2 if str(step)[0] == "2" else step * 2
    return step


def _pinned(spec: Any, value: float) -> str:
    """``"at its lower bound 0"`` if ``value`` sits on a bound (:meth:`aerobat.core.maneuver.ParameterSpec.pinned`),
    else empty."""
    side = spec.pinned(value)
    return f"at its {side} bound {spec.lower if side == 'lower' else spec.upper:g}" if side else ""


def _plotly_js() -> bytes:
    """plotly.js as the ``plotly`` package ships it (the compare page's figure; no network)."""
    try:
        from plotly.offline import get_plotlyjs
    except ImportError:  # the page falls back to its PNG
        raise NotFound("assets/plotly.min.js: plotly is not installed (pip install 'aerobat[viewers]')") from None
    return str(get_plotlyjs()).encode()


def _environment() -> Any:
    from jinja2 import Environment, PackageLoader, select_autoescape

    env = Environment(loader=PackageLoader("aerobat.browse", "templates"), autoescape=select_autoescape(["html"]))
    env.filters["num"] = lambda v, d=4: "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) \
        else f"{v:.{d}g}"
    env.filters["when"] = lambda s: "—" if not s else str(s)[:19].replace("T", " ")
    env.filters["json"] = json_text
    env.filters["summary"] = job_summary
    env.globals["zip"] = zip
    return env


class Site:
    """The pages of one store.

    Parameters
    ----------
    path : the store (opened read-only; a file that is not an aerobat store is refused).
    static : pages for a static export (no live polling, replays only of the default trials, and no figures
        of study sessions unless ``study_figures``: a study of hundreds of vehicles would take minutes).
    cache : folder for drawn figures and replays (default: a temporary one, removed by :meth:`close`).
    """

    def __init__(self, path: str | Path, *, static: bool = False, cache: Path | None = None,
                 study_figures: bool = False) -> None:
        self.store = Store(path, create=False)
        self.static = static
        self.study_figures = study_figures
        self._own_cache = cache is None
        self.cache = Path(tempfile.mkdtemp(prefix="aerobat-browse-")) if cache is None else cache
        self._lock = threading.RLock()
        self._env = _environment()
        self.compared: tuple[int, ...] = ()  # a static export's comparison (its index links to it)

    def close(self) -> None:
        """Close the store (after the page being drawn, if any) and remove the temporary figure cache."""
        with self._lock:
            self.store.close()
        if self._own_cache:
            shutil.rmtree(self.cache, ignore_errors=True)

    def __enter__(self) -> Site:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------- routing
    def get(self, page: str, query: dict[str, str] | None = None) -> tuple[str, bytes]:
        """``(content type, bytes)`` of a relative path; :class:`NotFound` for anything else."""
        page = page.lstrip("/") or "index.html"
        match = _PAGE.match(page)
        if match is None:
            raise NotFound(f"no page {page!r} (pages: index.html, session-ID.html, study-ID.html, compare.html)")
        g = match.groups()
        with self._lock:
            if g[0]:
                page_number = 1 if g[1] is None else _id(g[1], "page")
                return "text/html", self.index(query or {}, page=page_number).encode()
            if g[2]:
                return "text/html", self.session_page(self._session(g[2])).encode()
            if g[3]:
                return "text/html", self.study_page(self._study(g[3])).encode()
            if g[4]:
                return "application/json", json.dumps(self.progress(self._session(g[4]))).encode()
            if g[5]:
                return "image/png", self.session_figure(self._session(g[5]), g[6]).read_bytes()
            if g[7]:
                trial = None if g[8] == "default" else _id(g[8], "trial")
                return "text/html", self.replay(self._session(g[7]), trial).read_bytes()
            if g[9]:
                return "image/png", self.study_figure(self._study(g[9]), g[10]).read_bytes()
            if g[11]:
                return "image/png", self.compare_figure(self._ids(g[11], "compare figure ")).read_bytes()
            if g[12]:
                return "text/javascript", _plotly_js()
            ids = (query or {}).get("ids", "")
            return "text/html", self.compare_page(self._ids(ids, "compare: ids=")).encode()

    def _session(self, text: str) -> int:
        try:
            return self.store.resolve_session(_id(text, "session"))
        except SessionNotFound as exc:
            raise NotFound(str(exc)) from None

    def _study(self, text: str) -> int:
        try:
            return self.store.resolve_study(_id(text, "study"))
        except SessionNotFound as exc:
            raise NotFound(str(exc)) from None

    def _ids(self, text: str, where: str) -> list[int]:
        """Two to :data:`MAX_COMPARED` distinct sessions, in the order given (repeats dropped)."""
        words = [v for v in re.split(r"[,\s-]+", text.strip()) if v]
        shown = repr(text if len(text) <= 60 else text[:60] + "…")
        if not all(v.isascii() and v.isdigit() for v in words):
            raise ConfigError(f"{where}{shown}: expected session ids separated by commas")
        ids = list(dict.fromkeys(_id(v, "session") for v in words))
        if not 2 <= len(ids) <= MAX_COMPARED:
            raise ConfigError(f"{where}{shown}: choose two to {MAX_COMPARED} different sessions")
        return [self._session(str(sid)) for sid in ids]

    def _render(self, template: str, **values: Any) -> str:
        return str(self._env.get_template(template).render(static=self.static, db=str(self.store.path), **values))

    # ---------------------------------------------------------- pages
    def index(self, params: Mapping[str, str] | None = None, *, page: int = 1) -> str:
        """A page of the sessions table: the server's filtered, sorted and paged in the database; a static
        export's ``index.html``, ``index-2.html``… each :data:`PAGE_ROWS` sessions (study sessions are on
        their study's page), filtered and sorted in the page by the browser."""
        params = dict(params or {})
        if self.static:
            query = SessionQuery(limit=PAGE_ROWS, offset=(page - 1) * PAGE_ROWS)
        else:
            if "page" in params:
                page = _id(params["page"], "page") if params["page"].isascii() and params["page"].isdigit() \
                    else _bad("page", params["page"], "a page number")
            if page < 1:
                _bad("page", str(page), "a page number from 1")
            query = session_query(params, limit=PAGE_ROWS, offset=(page - 1) * PAGE_ROWS)
        found = self.store.query_sessions(query, counts=True)
        if page > found.pages:
            raise NotFound(f"no page {page} of the sessions table (it has {found.pages})")
        chosen = {name: "" if getattr(query, name) is None else str(getattr(query, name))
                  for name in ("maneuver", "plant", "vehicle", "feedback", "rule", "status", "study", "tag")}
        choices = {name: [(v, n) for v, n in values] for name, values in found.counts.items()}
        for name, value in chosen.items():
            if value and value not in {v for v, _ in choices[name]}:
                choices[name].append((value, 0))  # the chosen value is offered even if nothing has it now
        return self._render("index.html", found=found, query=query, rows=[session_row(r) for r in found.rows],
                            compared=self.compared if self.static else (),
                            studies=study_rows(self.store), choices=choices, chosen=chosen,
                            link=lambda **change: _index_link(params, self.static, **change))

    def session_page(self, session_id: int) -> str:
        """One session: figures, tables, maneuver, design, plant, replay, tags and notes."""
        store = self.store
        rec = store.session(session_id)
        mrec = store.maneuver(rec.maneuver_id)
        drec = store.design(rec.design_id)
        prec = store.plant(rec.plant_id)
        row = session_rows(store, session_id=session_id)[0]
        iterations = store.iterations(session_id)
        mask = np.array(mrec.position_mask, dtype=bool)
        table = []
        for it in iterations:
            position = float(np.linalg.norm(it.error[mask])) if mask.any() and np.isfinite(it.error[mask]).all() \
                else None
            table.append({"it": it, "position_m": position, "error": it.error.tolist()})
        measured = [it.index for it in iterations if it.status is IterationStatus.OK and it.trajectory_rows > 0]
        specs = parameters_of(mrec.spec, len(mrec.parameter_names))
        parameters = [{"name": n, "unit": u, "guess": float(drec.p_guess[k]), "nominal": float(drec.p_nominal[k]),
                       "start": float(rec.start_params[k]), "learned": float(rec.current_params[k]),
                       "description": specs[k].description if specs else "",
                       "bounds": f"[{specs[k].lower:g}, {specs[k].upper:g}]" if specs else "",
                       "pinned": _pinned(specs[k], float(rec.current_params[k])) if specs else ""}
                      for k, (n, u) in enumerate(zip(mrec.parameter_names, mrec.parameter_units, strict=True))]
        curves = [self._error_curve(session_id, f"session {session_id}")]
        return self._render(
            "session.html", rec=rec, row=row, mrec=mrec, drec=drec, prec=prec, table=table, measured=measured,
            parameters=parameters, vehicle=store.vehicle(prec.vehicle_id).config,
            design_vehicle=store.vehicle(drec.vehicle_id).config, tags=rec.tags,
            notes=[f"{at}  {text}" for at, text in rec.notes],
            replays=(["default"] if self.static else ["default", *measured]), figures=self._draws(row.study_id),
            curves=curves, dtick=_dtick(curves),
            live=not self.static and rec.display_state == SessionStatus.RUNNING)  # running, and not killed

    def progress(self, session_id: int) -> dict[str, Any]:
        """A running session's counters (the page polls them for live progress)."""
        row = session_rows(self.store, session_id=session_id)[0]
        return {"session": row.id, "status": row.status, "trials": row.n_records, "measured": row.n_measured,
                "target": row.target_iterations, "last_position_error_m": row.last_position_error_m,
                "updated_at": row.updated_at}

    def study_page(self, study_id: int) -> str:
        """One study: its jobs, failed ones first, its sessions and the figures in its output folder."""
        study = self.store.study(study_id)
        jobs = self.store.study_jobs(study_id)
        sessions = [session_row(s) for s in self.store.study_sessions(study_id)]
        failed = [j for j in jobs if j.status is JobStatus.FAILED]
        return self._render("study.html", study=study, jobs=jobs, failed=failed,
                            sessions=sessions, figures=self._study_figures(study.out_dir))

    def compare_page(self, ids: Sequence[int]) -> str:
        """Two or more sessions: what differs between them, their position errors over the trials in an
        interactive figure (and a PNG), and their parameters side by side with meaning and bounds."""
        comparison = self.store.compare_many(ids)
        differences = comparison.differences
        rows = {sid: session_rows(self.store, session_id=sid)[0] for sid in comparison.ids}
        legend_fields = [f for f in ("maneuver", "plant", "vehicle flown", "feedback", "rule", "seed")
                         if f in differences]
        values = dict(comparison.rows)
        labels = {}
        for k, sid in enumerate(comparison.ids):
            said = [f"{'vehicle' if f == 'vehicle flown' else f} {rows[sid].rule if f == 'rule' else values[f][k]}"
                    for f in legend_fields]
            labels[sid] = f"session {sid}" + (f": {', '.join(said)}" if said else "")
        curves = [self._error_curve(sid, labels[sid]) for sid in comparison.ids]
        return self._render("compare.html", ids=comparison.ids, rows=comparison.rows, differences=differences,
                            labels=labels, parameters=self._compared_parameters(comparison), curves=curves,
                            dtick=_dtick(curves), key="-".join(map(str, comparison.ids)))

    def _error_curve(self, session_id: int, label: str) -> dict[str, Any]:
        """A session's position error per measured trial, as a plotly trace."""
        mask = np.array(self.store.maneuver(self.store.session(session_id).maneuver_id).position_mask, dtype=bool)
        its = [it for it in self.store.iterations(session_id) if it.status is IterationStatus.OK]
        points = [(it.index, float(np.linalg.norm(it.error[mask]))) for it in its
                  if mask.any() and np.isfinite(it.error[mask]).all()]
        return {"x": [t for t, _ in points], "y": [e for _, e in points], "name": label, "mode": "lines+markers",
                "type": "scatter", "hovertemplate": "trial %{x}: %{y:.4g} m<extra>" + label + "</extra>"}

    def _compared_parameters(self, comparison: Any) -> list[dict[str, Any]]:
        """Each parameter's name, meaning, unit and bounds, and per session its value and whether it is pinned
        at a bound (within 1e-4 of the parameter's scale, as the design says)."""
        if not comparison.parameters:
            return []
        specs = parameters_of(self.store.maneuver(self.store.session(comparison.ids[0]).maneuver_id).spec,
                              len(comparison.parameters))
        out = []
        for k, (name, unit, values) in enumerate(comparison.parameters):
            spec = specs[k] if specs else None
            cells = [{"value": value, "pinned": _pinned(spec, value) if spec is not None else ""}
                     for value in values]
            out.append({"name": name, "unit": unit, "description": spec.description if spec else "",
                        "bounds": f"[{spec.lower:g}, {spec.upper:g}]" if spec else "", "cells": cells,
                        "same": len(set(values)) == 1})
        return out

    # ---------------------------------------------------------- figures
    def _draws(self, study_id: int | None) -> bool:
        """Whether a session's page shows figures and replays (a static export leaves study sessions' out)."""
        return not self.static or study_id is None or self.study_figures

    def _folder(self, session_id: int) -> Path:
        rec = self.store.session(session_id)
        folder = self.cache / f"session-{session_id}" / f"v{rec.n_records}-{rec.display_state}"
        folder.mkdir(parents=True, exist_ok=True)
        return folder

    def session_figure(self, session_id: int, name: str) -> Path:
        """``learning.png`` or ``side_views.png`` of a session (drawn once per stored state)."""
        from aerobat.experiments.reports import session_figures

        path = self._folder(session_id) / f"{name}.png"
        if not path.exists():
            session_figures(self.store, session_id, path.parent)
        if not path.exists():
            raise NotFound(f"session {session_id}: no {name}.png (no measured trial yet)")
        return path

    def replay(self, session_id: int, trial: int | None) -> Path:
        """The 3D replay HTML (``aerobat replay``'s) of one trial, or of the first and last measured."""
        from aerobat.experiments.reports import session_replay

        path = self._folder(session_id) / f"replay-{'default' if trial is None else trial}.html"
        if not path.exists():
            try:
                session_replay(self.store, session_id, path, iterations=None if trial is None else [trial])
            except ConfigError as exc:
                raise NotFound(str(exc)) from None
        return path

    @staticmethod
    def _study_figures(out_dir: str | None) -> list[str]:
        if not out_dir or not Path(out_dir).is_dir():
            return []
        return sorted(p.name for p in Path(out_dir).glob("*.png"))

    def study_figure(self, study_id: int, name: str) -> Path:
        """A figure the study wrote to its output folder."""
        out_dir = self.store.study(study_id).out_dir
        if name not in self._study_figures(out_dir):
            raise NotFound(f"study {study_id}: no figure {name!r} in {out_dir or 'its output folder (none)'}")
        return Path(str(out_dir)) / name

    def compare_figure(self, ids: Sequence[int]) -> Path:
        """The position error of each session over its trials, overlaid (log scale)."""
        from aerobat.plotting.files import new_figure, save_figure

        key = "-".join(str(self._session(str(i))) for i in ids)
        versions = "-".join(str(self.store.session(i).n_records) for i in ids)
        path = self.cache / "compare" / f"{key}.v{versions}.png"
        if path.exists():
            return path
        fig = new_figure(figsize=(8, 4))
        ax = fig.subplots()
        for sid in ids:
            curve = self._error_curve(sid, f"session {sid}")  # the interactive figure's points
            if curve["x"]:
                ax.semilogy(curve["x"], curve["y"], ".-", label=curve["name"])
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # trials are whole numbers
        ax.set_xlabel("trial")
        ax.set_ylabel("position error [m]")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend()
        path.parent.mkdir(parents=True, exist_ok=True)
        return save_figure(fig, path)

    # ---------------------------------------------------------- export
    def export_pages(self, compare: Sequence[int] = ()) -> list[str]:
        """The relative paths :meth:`export` writes, ``index.html`` last.

        ``compare.html`` and its figure are exported only for the sessions in ``compare``; a session's
        figures are listed only if it has a measured trial (and, in a static site, is not a study's).
        """
        pages = [*(f"index-{n}.html" for n in range(2, self.store.query_sessions(
            SessionQuery(limit=PAGE_ROWS)).pages + 1))]
        for row in session_rows(self.store):
            pages.append(f"session-{row.id}.html")
            if row.n_measured and self._draws(row.study_id):
                pages += [f"session-{row.id}/learning.png", f"session-{row.id}/side_views.png",
                          f"session-{row.id}/replay-default.html"]
        for study in study_rows(self.store):
            pages.append(f"study-{study.id}.html")
            pages += [f"study-{study.id}/{name}" for name in self._study_figures(study.out_dir)]
        if compare:
            pages += ["compare.html", f"compare/{'-'.join(map(str, compare))}.png"]
        return [*pages, "assets/plotly.min.js", "index.html"]  # plotly.js (4.8 MB) after the pages: a full disk
        # stops the export with as many pages written as fit

    def export(self, folder: Path, *, compare: Sequence[int] = (), stores: Iterable[Any] = ()) -> list[Path]:
        """Write every page, figure and default replay as static files under ``folder``; the files written.

        Every name is checked before the first page is drawn (:func:`aerobat.fileio.check_output`,
        :func:`~aerobat.fileio.check_output_folder`): a name that is the store (this one, ``stores``
        or the default one, through any link, or its ``-wal``/``-shm``), a dangling link, a folder, a
        FIFO, a device or an SQLite file where a page goes, or a link or a file where a subfolder goes,
        is refused with :class:`ConfigError` and nothing is written. Each file is then written by
        :func:`aerobat.fileio.write_output`: into a temporary file that replaces the name, so a file
        or a link already there is replaced (the file a link points to is untouched) and a write that
        fails — a full disk is :class:`~aerobat.errors.DiskFull` — leaves the old file whole and no
        part of the new one. ``index.html`` is written last: a folder with a new index holds every
        page it links to.
        """
        protected = (self.store.path, *stores)
        compare = [self._session(str(sid)) for sid in compare]
        self.compared = tuple(compare)
        pages = self.export_pages(compare)
        for sub in sorted({Path(page).parent for page in pages} - {Path(".")}):
            check_output_folder(folder / sub, option="--export")
        for page in pages:
            if os.path.lexists(folder / page):
                check_output(folder / page, option="--export", force=True, stores=protected, devices=False)
        if not os.path.isdir(folder):  # the folder the caller named may be a link to one: that is followed
            make_output_folder(folder, option="--export")
        written: list[Path] = []
        made: list[Path] = []  # subfolders this export created: removed again if a failure leaves them empty
        try:
            for page in pages:
                try:
                    query = {"ids": ",".join(map(str, compare))} if page == "compare.html" else None
                    data = self.get(page, query)[1]
                except NotFound:
                    continue  # a session without a figure: its page says so
                sub = (folder / page).parent
                if sub != folder and not os.path.isdir(sub):
                    made.append(make_output_folder(sub, option="--export"))
                written.append(write_output(folder / page, data, option="--export", stores=protected))
        except BaseException:
            for sub in made:
                with contextlib.suppress(OSError):
                    sub.rmdir()  # only if empty
            raise
        return written
