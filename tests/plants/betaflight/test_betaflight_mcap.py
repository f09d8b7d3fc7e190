"""A Betaflight session's MCAP file (issues 26, 44): every trial's pose stream and path, the firmware's signals."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
from mcap.reader import make_reader

from aerobat.cli import main
from aerobat.plants.fpv.phases import SIGNAL_NAMES
from aerobat.store import Store
from browse_fixtures import check_session_mcap


def test_a_betaflight_session_reads_back_from_its_mcap_file(tmp_path, firmware):
    db, path = tmp_path / "bf.sqlite", tmp_path / "bf.mcap"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["learn", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "800", "--plant",
                     "betaflight", "--iterations", "2", "--db", str(db), "--out", str(tmp_path / "out")]) == 0
        assert main(["export", "last", "--db", str(db), "--format", "mcap", "--output", str(path)]) == 0
    with Store(db, create=False) as store:
        counts = check_session_mcap(path, store, 1)
        iterations = store.iterations(1)
    assert len([t for t in counts if t.endswith("/pose")]) == len([i for i in iterations if i.trajectory_rows]) >= 2
    with path.open("rb") as stream:
        records = [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(topics=["/firmware"])]
    assert [r["plant"] for r in records] == ["betaflight"] * len(iterations)
    assert all(r["info"]["firmware"].startswith("Betaflight 4.6") for r in records)
    assert [r["trial"] for r in records] == [i.index for i in iterations]
    assert [r["info"]["frames_sent"] for r in records] == [i.info.get("frames_sent") for i in iterations]
    # the trials overlaid (check_session_mcap checks t_s and the scene's paths): motion capture measures
    # neither the body rates nor the motor thrusts, so they are null on the state channels
    with path.open("rb") as stream:
        samples = [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(topics=["/trials/state"])]
    assert {s["trial"] for s in samples} == {i.index for i in iterations if i.trajectory_rows}
    for name in ("p_rad_s", "q_rad_s", "r_rad_s", "f1_n", "f2_n", "f3_n", "f4_n"):
        assert {s[name] for s in samples} == {None}, name
    assert None not in [s["p_est_rad_s"] for s in samples] and None not in [s["collective_m_s2"] for s in samples]
    # the firmware's own signals, a sample per radio frame of the maneuver (schema 7): every documented
    # field non-null, and they say what the firmware did: the roll set point reaches the program's 800 °/s
    # (the plant's feedback law adds its corrections to the program's rates), the true rate follows it,
    # the motors stay within 0..1
    flown = [i for i in iterations if i.trajectory_rows]
    assert sorted(t for t in counts if "firmware" in t) == sorted(
        ["/firmware", "/trials/firmware", *(f"/trial/{i.index}/firmware" for i in flown)])
    with path.open("rb") as stream:
        firmware = [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(
            topics=[f"/trial/{flown[0].index}/firmware"])]
    assert counts["/trials/firmware"] == sum(counts[f"/trial/{i.index}/firmware"] for i in flown)
    assert len(firmware) > 100 and set(firmware[0]) == {"trial", "t_s", *SIGNAL_NAMES}
    for name in SIGNAL_NAMES:
        assert None not in [s[name] for s in firmware], name
    t_s = np.array([s["t_s"] for s in firmware])
    assert np.all(np.diff(t_s) > 0) and -0.01 < t_s[0] < 0.01  # from the program's start
    column = lambda name: np.array([s[name] for s in firmware])  # noqa: E731
    setpoint, rate = column("setpoint_roll_deg_s"), column("rate_roll_deg_s")
    assert 720.0 < np.max(np.abs(setpoint)) < 1000.0, np.max(np.abs(setpoint))
    assert np.corrcoef(setpoint, rate)[0, 1] > 0.9
    motors = np.column_stack([column(f"motor{m}") for m in range(1, 5)])
    assert np.all((motors >= 0.0) & (motors <= 1.0)) and motors.max() > 0.5
    assert np.max(np.abs(column("p_roll"))) > 10.0  # the P term works during the flip
