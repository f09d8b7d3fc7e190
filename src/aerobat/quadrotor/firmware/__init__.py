"""The flight controller as a design model: Betaflight 4.6's stick-to-motor path, compiled.

The paper's first-principles model includes the vehicle's onboard rate controller (Sect. 3);
on a Betaflight quad that controller is Betaflight's: its rate curves and RC smoothing,
its PID with feedforward, its gyro and D-term filters, its mixer with air mode, its throttle
path. :class:`FirmwareModel` flies programs through them around an X-frame airframe, as a
``FinalStateModel`` the design takes (docs/method.md, "The model knows the firmware").

Modules: :mod:`.config` (the settings it reads), :mod:`.layout` (its vectors and the
firmware's scalings), :mod:`.filters`, :mod:`.rc_path`, :mod:`.pid`, :mod:`.mixer`,
:mod:`.loop` (one gyro sample), :mod:`.sticks` (a program as sticks), :mod:`.flight`
(the compiled flight) and :mod:`.model`.
"""

from aerobat.quadrotor.firmware.config import FirmwareConfig
from aerobat.quadrotor.firmware.model import Fidelity, FirmwareModel, FirmwareTrajectory

__all__ = ["Fidelity", "FirmwareConfig", "FirmwareModel", "FirmwareTrajectory"]
