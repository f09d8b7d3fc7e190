"""Statuses and notes travel as enums and values, not as text (issue #29, item 1).

* no status or state is compared with a string literal outside the command line, the
  browser's pages and the store's codec (the edges where text becomes an enum);
* no message is split on ``";"`` — written out or through a named constant such as
  ``WARNING_PREFIX`` — to get its notes back: an iteration carries them
  (:class:`~aerobat.core.notes.IterationNote`), the store keeps them in their own column
  (schema 6), and only the migration of rows written before that reads them out of a
  stored message (:data:`ALLOWED_SPLITS`);
* the store hands back enums, and the notes of a stored iteration.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest

from aerobat.core.learning import Iteration, IterationStatus, SessionStatus
from aerobat.core.notes import IterationNote, NoteKind, message_with_notes
from aerobat.store.migrations import legacy_notes_from_message

PACKAGE = Path(__file__).resolve().parents[2] / "src" / "aerobat"
EDGES = ("cli/", "browse/", "store/codec.py")
"""Where text becomes an enum: the command line, the browser's pages, the store's codec."""
STATUS_NAMES = {"status", "state", "display_state", "kind"}

_MANEUVER = "a maneuver spec's kind names its registered class (aerobat.core.registry): a registry key"
_CORRECTION = ("CorrectionKind is a Literal, not yet an enum: a design's correction_kind also holds 'none' "
               "(identification's stand-in design), so it changes with the design and store columns (follow-up)")
_FIRMWARE = "values of Betaflight's own settings (rates_type, throttle_limit_type) as its CLI writes them: file text"
ALLOWED_TEXT_KINDS = {
    ("core/correction.py", "kind == 'inverse'"): _CORRECTION,
    ("core/correction.py", "kind == 'tsvd'"): _CORRECTION,
    ("core/correction.py", "kind == 'damped'"): _CORRECTION,
    ("core/rules/scaled.py", "kind == 'tsvd'"): _CORRECTION,
    ("core/rules/scaled.py", "kind == 'damped'"): _CORRECTION,
    ("core/rules/registry.py", "kind == 'rule'"): "reads a stored rule table: where its text becomes a ScheduleKind",
    ("core/rules/registry.py", "kind == 'paper'"): "reads a stored rule table: where its text becomes a ScheduleKind",
    ("core/rules/registry.py", "kind == 'constant'"):
        "reads a stored rule table: where its text becomes a ScheduleKind",
    ("experiments/reports.py", "kind == 'translation'"): _MANEUVER,
    ("experiments/reports.py", "kind in ('flip', 'multiflip')"): _MANEUVER,
    ("logs/blackbox_header.py", "kind == 'P'"): "a blackbox header's frame letter (I, P): log file text at the edge",
    **{("firmware/betaflight/settings.py", f"kind == {word!r}"): _FIRMWARE
       for word in ("ACTUAL", "BETAFLIGHT", "RACEFLIGHT", "KISS", "QUICK", "SCALE", "CLIP")},
}
"""(module, comparison) of a ``kind`` with text that stays text, with the reason."""


def _is_status(node: ast.expr) -> bool:
    """``x.status``, ``status``, ``x.status.value``, ``row["status"]`` (and the same for ``state``)."""
    if isinstance(node, ast.Attribute) and node.attr == "value":
        node = node.value
    if isinstance(node, ast.Attribute):
        return node.attr in STATUS_NAMES
    if isinstance(node, ast.Name):
        return node.id in STATUS_NAMES
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
        return node.slice.value in STATUS_NAMES
    return False


def _is_text(node: ast.expr) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        return any(_is_text(e) for e in node.elts)
    return False


def _sources(*, edges: bool) -> list[tuple[str, ast.AST]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        where = path.relative_to(PACKAGE).as_posix()
        if edges or not where.startswith(EDGES):
            out.append((where, ast.parse(path.read_text())))
    return out


def test_no_status_is_compared_with_a_string_outside_the_edges():
    found = []
    for where, tree in _sources(edges=False):
        for node in ast.walk(tree):
            if not isinstance(node, ast.Compare):
                continue
            operands = [node.left, *node.comparators]
            for left, op, right in zip(operands, node.ops, operands[1:], strict=False):
                key_lookup = isinstance(op, ast.In | ast.NotIn) and _is_status(right)  # "gamma" in state: a key
                if not key_lookup and ((_is_status(left) and _is_text(right)) or
                                       (_is_text(left) and _is_status(right))) and \
                        (where, ast.unparse(node)) not in ALLOWED_TEXT_KINDS:
                    found.append(f"{where}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "compare the enum (IterationStatus, SessionStatus, JobStatus, StudyKind, ErrorKind…), not " \
        "its text:\n" + "\n".join(found)


def test_every_allowed_text_kind_is_still_there():
    """An exception that no longer occurs is removed from the list (it would hide a new one written the same)."""
    seen = {(where, ast.unparse(node)) for where, tree in _sources(edges=False) for node in ast.walk(tree)
            if isinstance(node, ast.Compare)}
    assert set(ALLOWED_TEXT_KINDS) <= seen, sorted(set(ALLOWED_TEXT_KINDS) - seen)


ALLOWED_SPLITS = {
    ("store/migrations.py", "legacy_notes_from_message"):
        "reads the notes out of the messages of rows written before schema 6, once, when migrating them",
}
"""(module, function) that may split text on a ``;`` separator, with the reason."""


def _string_constants() -> dict[str, str]:
    """Every module-level ``NAME = "text"`` of the package (the separators a split could be given by name)."""
    names: dict[str, str] = {}
    for _, tree in _sources(edges=True):
        for node in getattr(tree, "body", []):
            value = node.value if isinstance(node, ast.Assign | ast.AnnAssign) else None
            targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                names.update({t.id: value.value for t in targets if isinstance(t, ast.Name)})
    return names


def _separator(node: ast.expr, constants: dict[str, str]) -> str | None:
    """The text ``node`` stands for: a literal, or a named constant (``WARNING_PREFIX``, ``notes.WARNING_PREFIX``)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else None
    return constants.get(name) if name else None


def _splits_on_semicolons(constants: dict[str, str]) -> list[str]:
    found = []
    for where, tree in _sources(edges=True):
        functions = [(n.name, n) for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
        owner = {id(inner): name for name, fn in functions for inner in ast.walk(fn)}  # innermost last wins
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                    node.func.attr in ("split", "rsplit", "partition", "rpartition") and \
                    any(";" in (_separator(a, constants) or "") for a in node.args) and \
                    (where, owner.get(id(node), "<module>")) not in ALLOWED_SPLITS:
                found.append(f"{where}:{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_text_is_split_on_semicolons():
    found = _splits_on_semicolons(_string_constants())
    assert not found, "an iteration's notes are Iteration.notes; SQL is split by sqlite3.complete_statement:\n" + \
        "\n".join(found)


def test_the_split_check_sees_a_separator_given_by_name():
    constants = {**_string_constants(), "SEP": "; warning: "}
    for code in ('text.split("; x")', "text.split(SEP)", "head.partition(notes.SEP)"):
        tree = ast.parse(code)
        call = tree.body[0].value  # type: ignore[attr-defined]
        assert any(";" in (_separator(a, constants) or "") for a in call.args), code
    assert _string_constants()["WARNING_PREFIX"] == "; warning: "


@pytest.mark.parametrize("notes", [
    (),
    (IterationNote.held("t1"),),
    (IterationNote.held("t1"), IterationNote.held("phi")),
    (IterationNote(NoteKind.PINNED_AT_BOUND, "t2", "t2 (coast) pinned at a bound for 8 corrections: infeasible"),),
    (IterationNote.held("a"), IterationNote(NoteKind.PINNED_AT_BOUND, "b", "b (x) pinned: one"),
     IterationNote(NoteKind.PINNED_AT_BOUND, "c", "c (y) pinned: two")),
])
def test_the_migration_reads_back_the_notes_an_old_message_says(notes):
    message = message_with_notes("measured (latency 3 ms)", notes)
    assert legacy_notes_from_message(message) == notes


def test_a_message_says_its_notes_as_it_always_did():
    notes = (IterationNote.held("a"), IterationNote.held("b"),
             IterationNote(NoteKind.PINNED_AT_BOUND, "b", "b (x) pinned at a bound for 8 corrections: bad"))
    assert message_with_notes("ok", notes) == \
        "ok; held at a bound: a, b; warning: b (x) pinned at a bound for 8 corrections: bad"
    it = Iteration(1, 1, IterationStatus.OK, np.zeros(2), np.zeros(1), 1.0, 1.0, np.zeros(2),
                   message_with_notes("ok", notes), None, notes)
    assert it.warnings == ("b (x) pinned at a bound for 8 corrections: bad",)


def test_status_properties_say_what_strings_used_to():
    assert [s for s in IterationStatus if s.retry] == [IterationStatus.NO_TRIGGER, IterationStatus.LOST]
    assert [s for s in IterationStatus if s.measured] == [IterationStatus.OK]
    assert SessionStatus("completed") is SessionStatus.COMPLETED


def test_the_store_takes_an_iteration_and_hands_back_its_notes_and_enums(tmp_path):
    from aerobat.core.design import DesignStatus
    from aerobat.core.maneuver import ErrorKind
    from aerobat.store import Store
    from aerobat.store.records import JobStatus, StudyKind
    from browse_fixtures import DESIGN, FLIP, VEHICLE

    notes = (IterationNote.held("t1"),
             IterationNote(NoteKind.PINNED_AT_BOUND, "t2", "t2 (coast) pinned at a bound for 8 corrections: bad"))
    params = DESIGN.p_nominal.copy()
    step = np.full(params.shape, 1e-3)
    sent = Iteration(1, 1, IterationStatus.OK, params, np.linspace(0.1, 0.2, len(FLIP.errors)), 0.5, 1.0, step,
                     message_with_notes("measured", notes), None, notes)
    with Store(tmp_path / "s.sqlite") as store:
        sid = store.create_session(vehicle=VEHICLE, plant_kind="nominal", plant_config={}, maneuver=FLIP,
                                   design=DESIGN, seed=None, rule={"name": "paper"}, target_iterations=1,
                                   start_params=params)
        store.append_iteration(sid, sent)
        store.finish_session(sid, SessionStatus.COMPLETED, "1 measured iteration")
        study = store.create_study("robustness", {})
        store.record_study_job(study, "a", {}, {}, status=JobStatus.FAILED, error="x")
        got = store.iterations(sid)[0]
        assert got.status is IterationStatus.OK and got.notes == notes and got.message == sent.message
        stored = store._db.execute("SELECT notes FROM iterations WHERE session_id = ?", (sid,)).fetchone()[0]
        assert json.loads(stored) == [{"kind": "held_at_bound", "parameter": "t1", "text": "held at a bound"},
                                      {"kind": "pinned_at_bound", "parameter": "t2", "text": notes[1].text}]
        assert Iteration.from_json_dict(json.loads(json.dumps(sent.to_json_dict()))).notes == notes
        assert np.array_equal(got.next_params, sent.next_params)
        back = got.iteration()
        assert np.array_equal(back.next_params, sent.next_params) and back.warnings == sent.warnings
        assert store.session(sid).state is SessionStatus.COMPLETED
        assert store.list_sessions()[0].state is SessionStatus.COMPLETED
        drec = store.design(store.session(sid).design_id)
        assert drec.status is DesignStatus(DESIGN.status)
        rebuilt = drec.design(FLIP)
        assert all(np.array_equal(getattr(rebuilt, k), getattr(DESIGN, k)) for k in ("jacobian", "correction"))
        assert store.study_jobs(study)[0].status is JobStatus.FAILED
        assert store.study(study).kind is StudyKind.ROBUSTNESS
        assert all(isinstance(k, ErrorKind) for k in store.maneuver(1).error_kinds)
        assert store.maneuver(1).error_kinds == tuple(e.kind for e in FLIP.errors)


def test_study_kinds_are_an_enum_and_a_stored_name_of_its_own_still_reads(tmp_path):
    from aerobat import run_study
    from aerobat.errors import ConfigError
    from aerobat.store import Store, checksums
    from aerobat.store.records import StudyKind

    with Store(tmp_path / "s.sqlite") as store:
        with pytest.raises(ConfigError, match="expected one of robustness, rules, feedback, envelope, map"):
            run_study(store, "sweep", {}, [], workers=1)
        with pytest.raises(ConfigError, match="study kind 'sweep': allowed robustness, rules"):
            store.create_study("sweep", {})
        outcome = run_study(store, "envelope", {}, [], workers=1)
        assert store.study(outcome.study_id).kind is StudyKind.ENVELOPE
        with store._db:  # a study an older aerobat ran under a name of its own
            checksums.insert(store._db, "studies", {"id": 9, "kind": "sweep", "spec": "{}", "created_at": "t",
                                                    "command": "[]", "out_dir": None})
        assert [s.kind for s in store.list_studies()] == [StudyKind.ENVELOPE, "sweep"]
