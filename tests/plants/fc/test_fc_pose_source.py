"""Motion capture through libmotioncapture (its ``mock`` system: a static body at ≈100 Hz)."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("motioncapture", reason="motioncapture is not installed (pip install 'aerobat[fc]')")

from aerobat.errors import ConfigError  # noqa: E402
from aerobat.plants.fc import MotionCaptureSource, PoseSource  # noqa: E402

MOCK = {"rigid_bodies": "quad(0.5,-0.25,1.0,1,0,0,0)"}


def test_poses_arrive_stamped_in_order_and_latency_corrected():
    with MotionCaptureSource("mock", "quad", latency_s=0.004, options=MOCK) as source:
        assert isinstance(source, PoseSource)
        poses = []
        while len(poses) < 10:
            arrived = source.wait(1.0)
            assert arrived, "no frame within 1 s"
            poses += arrived
    frames = [p.frame for p in poses]
    assert frames == sorted(frames) and len(set(frames)) == len(frames)  # each pose handed out once, in order
    first = poses[0]
    assert first.position_m == (0.5, -0.25, 1.0) and first.quaternion_wxyz == (1.0, 0.0, 0.0, 0.0)
    assert first.true_position_m is None and first.on_floor is None  # a real system knows no truth
    assert all(p.received_s - p.measured_s == pytest.approx(0.004) for p in poses)
    assert all(p.received_s <= time.monotonic() for p in poses)
    rate_hz = (len(poses) - 1) / (poses[-1].received_s - poses[0].received_s)
    assert 20.0 < rate_hz < 500.0  # the mock system's ≈100 Hz (slower under load)


def test_wait_returns_nothing_after_its_timeout_once_closed():
    source = MotionCaptureSource("mock", "quad", options=MOCK)
    source.close()
    started = time.monotonic()
    assert source.wait(0.2) == [] and time.monotonic() - started < 0.3


@pytest.mark.parametrize("system, body, message", [
    ("kinect", "quad", r"^--mocap 'kinect': allowed 'vicon', 'optitrack'"),
    ("mock", "other", r"^--mocap mock: no frame with rigid body 'other' within 0.3 s"),
])
def test_a_source_that_cannot_track_the_vehicle_is_refused_in_one_line(system, body, message):
    with pytest.raises(ConfigError, match=message) as info:
        MotionCaptureSource(system, body, options=MOCK, first_frame_timeout_s=0.3)
    assert "\n" not in str(info.value)
