"""A :class:`~.tune.Tune` as Betaflight 4.6 SITL commands, and the report of what became of each setting.

Every setting of the profiles the quad flew ends in exactly one of four lists:

* **applied**: a 4.6 name with a value this SITL build accepts (checked against
  ``sitl_settings.json``, read from the firmware itself);
* **translated**: a name (or meaning) that changed between the writer's version and 4.6, applied
  under its 4.6 form (``dshot_idle_value`` → ``motor_idle``; before 4.6 ``d_roll`` was the *maximum*
  D and ``d_min_roll`` the base, in 4.6 ``d_roll`` is the base and ``d_max_roll`` the maximum);
* **refused**, with the reason: hardware the SITL does not have (serial ports, OSD, VTX, beeper,
  battery, board alignment, ESC protocol), 4.6 settings not compiled into the SITL build
  (``dyn_notch_*``, RPM filter), settings removed or changed in meaning since the writer's version,
  values 4.6 does not accept;
* **pinned**: what aerobat's pilot relies on stays aerobat's (``settings.toml``): the ARM and ANGLE
  switches (``aux``), AIR MODE, the QUADX mixer, the channel map, arming (``pwr_on_arm_grace``,
  ``small_angle``), the throttle-low threshold (``min_check``), failsafe, the runaway take-off check.

Simplified tuning: the sliders (``simplified_*``) are applied as settings, and the PIDs and
filters as the file states them. The firmware does not recompute PIDs from the sliders by itself
(only ``simplified_tuning apply`` in the CLI, the configurator or the OSD menu do,
config/simplified_tuning.c), so the stored PIDs are what the quad flew; aerobat never runs
``simplified_tuning apply``.

A name that is neither a 4.6 setting nor in the rename table below is an error naming the line
(:class:`~.tune.TuneError`): a typo must not be flown as the default. So is a value that is not one
of its setting's type as the firmware's CLI reads it (``1e2``, ``45.9``, ``4_5`` or ``abc`` for an
integer: :class:`~.sitl_table.Verdict` ``MALFORMED``), whatever the version that wrote it; a value
of the right type that 4.6 does not take (out of range, a lookup name it does not have) is refused.
Every value applied is written as the firmware prints it back (``+045`` → ``45``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from .cli_grammar import parse_integer, shown
from .settings import PINNED
from .sitl_table import SitlTable, Verdict, load_table
from .tune import Tune, TuneError, TuneKind

__all__ = ["PINNED", "TuneReport", "translate"]

_PINNED_COMMANDS = {
    "aux": "mode switches: aerobat's ARM on AUX1 and ANGLE on AUX2 replace the quad's mode ranges",
    "map": "channel order: aerobat's radio sends AETR1234",
    "mixer": "the physics flies a QUADX",
}
_HARDWARE_COMMANDS = {
    "serial": "serial ports", "beacon": "beeper", "beeper": "beeper", "led": "LED strip", "color": "LED strip",
    "mode_color": "LED strip", "resource": "pin mapping", "timer": "timer mapping", "dma": "DMA mapping",
    "vtx": "video transmitter", "vtxtable": "video transmitter", "vtx_info": "video transmitter",
    "osd_layout": "OSD", "board_name": "board identity", "manufacturer_id": "board identity",
    "mcu_id": "board identity", "signature": "board identity", "adjrange": "in-flight adjustments by switch "
    "(aerobat's radio sends only sticks, ARM and ANGLE)", "rxrange": "radio calibration", "rxfail": "radio failsafe "
    "values", "mmix": "custom mixer", "smix": "servo mixer", "servo": "servos", "gpspids": "GPS",
    "simplified_tuning": "aerobat never recomputes PIDs from the sliders",
    "header": "recorded in the log, not a setting",
}
# (prefix, reason): refused whatever the version
_HARDWARE_PREFIXES = (
    (("serial", "rx_", "spektrum", "sbus", "crsf", "srxl", "ibus", "msp_", "tlm_", "frsky", "hott", "telemetry",
      "ltm", "smartport", "mavlink", "rssi", "fport", "ghst", "elrs", "expresslrs", "cc2500", "rc_channel"),
     "receiver and serial links: aerobat's radio sends RC packets to the SITL directly"),
    (("osd_", "vtx_", "vcd_", "max7456", "displayport", "led_", "ledstrip", "beeper", "dshot_beacon", "camera",
      "pinio", "box_user", "tlm", "cms_"), "OSD, VTX, LED, beeper and camera hardware: absent in the SITL"),
    (("bat_", "vbat_scale", "vbat_divider", "vbat_multiplier", "vbat_max", "vbat_min", "vbat_warning", "vbat_full",
      "vbat_hyst", "vbat_detect", "vbat_cutoff", "vbat_duration", "vbat_lpf", "vbat_sag", "ibat", "current_meter",
      "battery_meter", "force_battery", "report_cell", "lvc", "cbat"), "battery measurement: the SITL has no battery"),
    (("align_", "gyro_1_", "gyro_2_", "gyro_to_use", "gyro_hardware", "acc_calibration", "acc_trim", "acc_hardware",
      "mag_", "baro_", "gyro_offset", "gyro_calib", "gyro_overflow", "rangefinder", "opticalflow"),
     "sensor hardware and its mounting: the SITL is given gyro and attitude in body axes"),
    (("motor_pwm", "dshot", "motor_poles", "use_unsynced_pwm", "motor_kv", "min_throttle", "max_throttle",
      "esc_sensor", "rpm_filter", "gyro_rpm_notch", "dterm_rpm_notch", "rpm_notch", "dyn_idle", "idle_",
      "rpm_limit", "motor_output_reordering"),
     "ESC protocol and RPM telemetry: the SITL's motor output is a 0..1 command with no ESC telemetry"),
    (("blackbox", "debug_mode", "sdcard", "flash"), "logging: the SITL writes no blackbox"),
    (("gps_", "nav_", "alt_hold", "pos_hold", "ap_"), "GPS and autopilot: not compiled into the SITL"),
    (("name", "craft_name", "pilot_name", "display_name", "usb_", "system_hse", "cpu_overclock", "task_statistics",
      "dashboard", "mco", "timezone", "box_"), "identity and system hardware"),
)
# 4.2-4.5 names that became another 4.6 name with the same meaning (name → (4.6 name, since))
_RENAMES: dict[str, tuple[str, str]] = {
    "dterm_lowpass_type": ("dterm_lpf1_type", "4.3"), "dterm_lowpass_hz": ("dterm_lpf1_static_hz", "4.3"),
    "dterm_lowpass2_type": ("dterm_lpf2_type", "4.3"), "dterm_lowpass2_hz": ("dterm_lpf2_static_hz", "4.3"),
    "dyn_lpf_dterm_min_hz": ("dterm_lpf1_dyn_min_hz", "4.3"), "dyn_lpf_dterm_max_hz": ("dterm_lpf1_dyn_max_hz", "4.3"),
    "dyn_lpf_dterm_curve_expo": ("dterm_lpf1_dyn_expo", "4.3"),
    "gyro_lowpass_type": ("gyro_lpf1_type", "4.3"), "gyro_lowpass_hz": ("gyro_lpf1_static_hz", "4.3"),
    "gyro_lowpass2_type": ("gyro_lpf2_type", "4.3"), "gyro_lowpass2_hz": ("gyro_lpf2_static_hz", "4.3"),
    "dyn_lpf_gyro_min_hz": ("gyro_lpf1_dyn_min_hz", "4.3"), "dyn_lpf_gyro_max_hz": ("gyro_lpf1_dyn_max_hz", "4.3"),
    "dyn_lpf_curve_expo": ("gyro_lpf1_dyn_expo", "4.3"),
    "ff_interpolate_sp": ("feedforward_averaging", "4.3"), "ff_smooth_factor": ("feedforward_smooth_factor", "4.3"),
    "ff_boost": ("feedforward_boost", "4.3"), "ff_max_rate_limit": ("feedforward_max_rate_limit", "4.3"),
    "rc_smoothing_input_hz": ("rc_smoothing_setpoint_cutoff", "4.3"),
    "rc_smoothing_derivative_hz": ("rc_smoothing_feedforward_cutoff", "4.3"),
    "rc_smoothing_type": ("rc_smoothing", "4.3"),
    "airmode_activate_throttle": ("airmode_start_throttle_percent", "4.3"),
    "p_level": ("angle_p_gain", "4.5"),
    "dshot_idle_value": ("motor_idle", "4.5"),
    "d_min_gain": ("d_max_gain", "4.6"), "d_min_advance": ("d_max_advance", "4.6"),
    "simplified_dmax_gain": ("simplified_d_max_gain", "4.6"),
}
_VALUE_MAPS: dict[str, dict[str, str]] = {
    # 4.2 always interpolated; OFF and ON were "no averaging" in 4.3's terms
    "ff_interpolate_sp": {"OFF": "OFF", "ON": "OFF", "AVERAGED_2": "2_POINT", "AVERAGED_3": "3_POINT",
                          "AVERAGED_4": "4_POINT"},
    "rc_smoothing_type": {"FILTER": "ON"},
}
# names gone since the writer's version with no 4.6 equivalent
_REMOVED: dict[str, str] = {
    "ff_spike_limit": "removed in 4.3 (feedforward_jitter_factor works differently)",
    "anti_gravity_mode": "removed in 4.3 (anti-gravity reworked)",
    "anti_gravity_threshold": "removed in 4.3 (anti-gravity reworked)",
    "vbat_pid_gain": "removed in 4.3 (vbat_sag_compensation replaces it)",
    "rc_smoothing_auto_smoothness": "4.3's rc_smoothing_auto_factor has another scale",
    "rc_smoothing_input_type": "removed in 4.3", "rc_smoothing_derivative_type": "removed in 4.3",
    "rc_interp": "removed in 4.3", "rc_interp_ch": "removed in 4.3", "rc_interp_int": "removed in 4.3",
    "dyn_notch_width_percent": "removed in 4.3 (dyn_notch_count); the dynamic notch is not in the SITL",
    "dyn_notch_range": "removed in 4.2", "i_level": "horizon mode reworked in 4.5 (no 1:1 setting)",
    "d_level": "horizon mode reworked in 4.5 (no 1:1 setting)", "p_mag": "magnetometer hold: no magnetometer",
    "i_mag": "magnetometer hold", "d_mag": "magnetometer hold", "level_limit": "removed",
}
# (writer version < this) → the setting changed meaning; refused with the reason
_MEANING_CHANGED: dict[str, tuple[tuple[int, int], str]] = {
    "anti_gravity_gain": ((4, 3), "scale changed in 4.3 (4.2: 1000..30000 = x1000; 4.3: 0..250, new algorithm)"),
    "rc_smoothing_auto_factor": ((4, 3), "4.2's auto smoothness (0..50) is not 4.3's auto factor"),
    "iterm_windup": ((4, 3), "semantics changed in 4.3"),
}
# the writer's default (D max, D min) per axis, for a diff that lists only one of the pair (flight/pid.c)
_D_DEFAULTS = {(4, 2): {"roll": (35, 23), "pitch": (38, 25), "yaw": (0, 0)},
               (4, 3): {"roll": (40, 30), "pitch": (46, 34), "yaw": (0, 0)}}
_FEATURES_APPLIED = frozenset({"ANTI_GRAVITY"})
_FEATURE = re.compile(r"(-?)([A-Za-z0-9_]+)")


@dataclass(frozen=True)
class TuneReport:
    """What became of every setting of a tune (each list in file order).

    applied : (4.6 name, value, line). translated : (old name, old value, 4.6 name, 4.6 value, line, why).
    refused : (name, value, line, reason). pinned : (name, the tune's value or "", reason).
    commands : the 4.6 CLI commands that apply the tune (``set`` and ``feature`` lines).
    """

    tune: Tune
    applied: tuple[tuple[str, str, int], ...]
    translated: tuple[tuple[str, str, str, str, int, str], ...]
    refused: tuple[tuple[str, str, int, str], ...]
    pinned: tuple[tuple[str, str, str], ...]
    commands: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())

    def values(self) -> dict[str, str]:
        """The 4.6 ``set`` values (last wins)."""
        out: dict[str, str] = {}
        for command in self.commands:
            if command.startswith("set "):
                name, _, value = command[4:].partition(" = ")
                out[name] = value
        return out

    def to_table(self) -> dict[str, object]:
        """The report as JSON-ready data: the tune's origin, each list as rows with named fields, the commands."""
        t = self.tune
        return {
            "source": t.source, "firmware": t.firmware, "version": t.version_text, "kind": t.kind.value,
            "active_profile": t.active_profile, "active_rateprofile": t.active_rateprofile,
            "applied": [{"name": n, "value": v, "line": line, "where": t.where(line)} for n, v, line in self.applied],
            "translated": [{"from": o, "from_value": ov, "name": n, "value": nv, "line": line, "where": t.where(line),
                            "why": why} for o, ov, n, nv, line, why in self.translated],
            "refused": [{"name": n, "value": v, "line": line, "where": t.where(line), "why": why}
                        for n, v, line, why in self.refused],
            "pinned": [{"name": n, "value": v, "why": why} for n, v, why in self.pinned],
            "notes": list(self.notes),
            "commands": list(self.commands),
        }

    def summary(self, whole: str = "aerobat tune FILE") -> str:
        """What a pilot must know before flying it, in a few lines: the counts, every translated setting, the
        refused ones grouped by why (hardware the SITL lacks, another profile…) and the notes; ``whole``: the
        command that prints every setting."""
        t = self.tune
        lines = [self.text().splitlines()[0]]
        lines += [f"  translated  {o} = {ov} -> {n} = {nv}  ({t.where(line)}: {why})"
                  for o, ov, n, nv, line, why in self.translated]
        groups: dict[str, list[str]] = {}
        for name, _, _, why in self.refused:
            groups.setdefault(why, []).append(name)
        for why, names in groups.items():
            listed = ", ".join(dict.fromkeys(names))
            lines.append(f"  refused     {len(names)} × {why}: {listed if len(listed) <= 100 else listed[:99] + '…'}")
        lines += [f"  note        {note}" for note in self.notes]
        lines.append(f"  ({len(self.applied)} applied and {len(self.pinned)} pinned settings not listed: `{whole}` "
                     f"prints every setting)")
        return "\n".join(lines)

    def text(self) -> str:
        """The report as people read it (one line per setting)."""
        t = self.tune
        # a log header's lines that are no setting (field layouts, dates, board) are counted apart, on one line
        header = [n for n, _, _, why in self.refused if why == _HARDWARE_COMMANDS["header"]]
        refused = [r for r in self.refused if r[3] != _HARDWARE_COMMANDS["header"]]
        head = [f"tune {t.source}: written by {t.firmware or 'an unknown firmware'} (version {t.version_text}), "
                f"profile {t.active_profile}, rate profile {t.active_rateprofile}: {len(self.applied)} applied, "
                f"{len(self.translated)} translated, {len(refused)} refused, {len(self.pinned)} pinned"
                + (f" ({len(header)} log header lines are no setting)" if header else "")]
        rows = [f"  applied     {n} = {v}  ({t.where(line)})" for n, v, line in self.applied]
        rows += [f"  translated  {o} = {ov} -> {n} = {nv}  ({t.where(line)}: {why})"
                 for o, ov, n, nv, line, why in self.translated]
        rows += [f"  refused     {n} = {v}  ({t.where(line)}: {why})" for n, v, line, why in refused]
        if header:
            rows.append(f"  not applied {len(header)} log header lines that are no setting: {', '.join(header)}")
        rows += [f"  pinned      {n}{' = ' + v if v else ''}  ({why})" for n, v, why in self.pinned]
        rows += [f"  note        {note}" for note in self.notes]
        return "\n".join(head + rows)


def _hardware(name: str) -> str | None:
    for prefixes, reason in _HARDWARE_PREFIXES:
        if name.startswith(prefixes):
            return reason
    return None


def _older(version: tuple[int, int, int], than: tuple[int, int]) -> bool:
    return version != (0, 0, 0) and version[:2] < than


class _Builder:
    def __init__(self, tune: Tune, table: SitlTable) -> None:
        self.tune, self.table = tune, table
        self.applied: list[tuple[str, str, int]] = []
        self.translated: list[tuple[str, str, str, str, int, str]] = []
        self.refused: list[tuple[str, str, int, str]] = []
        self.pinned: list[tuple[str, str, str]] = []
        self.sets: dict[str, str] = {}
        self.features: list[str] = []
        self.notes: list[str] = []

    def malformed(self, name: str, value: str, line: int, reason: str) -> TuneError:
        """Bad input: ``name = value`` at ``line`` is no value of its setting's type (the message says what is)."""
        return TuneError(f"{self.tune.source}: {self.tune.where(line)}: {name} = {shown(value)}: {reason}")

    def put(self, old: str, old_value: str, name: str, value: str, line: int, why: str = "") -> None:
        entry = self.table.get(name)
        if entry is None:
            reason = ("a 4.6 setting not compiled into the SITL build (its hardware is absent)"
                      if name in self.table.all_names else "not a Betaflight 4.6 setting")
            self.refused.append((old, old_value, line, reason if old == name else f"{name}: {reason}"))
            return
        checked = entry.checked(value)
        if checked.verdict is Verdict.MALFORMED:
            raise self.malformed(old if old == name else f"{old} (4.6's {name})", value, line, checked.reason)
        if checked.verdict is Verdict.REJECTED:
            self.refused.append((old, old_value, line, f"4.6's {name} = {checked.value}: {checked.reason}"))
            return
        value = checked.value
        self.sets[name] = value
        if old == name and not why:
            self.applied.append((name, value, line))
        else:
            self.translated.append((old, old_value, name, value, line, why))

    def setting(self, section: str, name: str, value: str, line: int) -> None:
        version = self.tune.version
        if name in PINNED:
            self.pinned.append((name, value, PINNED[name]))
            return
        hardware = None if name in _RENAMES else _hardware(name)
        if hardware is not None:
            self.refused.append((name, value, line, hardware))
            return
        changed = _MEANING_CHANGED.get(name)
        if changed is not None and _older(version, changed[0]):
            self.refused.append((name, value, line, changed[1]))
            return
        if name in _REMOVED and self.table.get(name) is None:
            self.refused.append((name, value, line, _REMOVED[name]))
            return
        if name in _RENAMES and (self.table.get(name) is None or name.startswith("d_min")):
            new, since = _RENAMES[name]
            mapped = _VALUE_MAPS.get(name, {})
            new_value = mapped.get(value.upper(), value) if mapped else value
            if name in _VALUE_MAPS and value.upper() not in mapped:
                self.refused.append((name, value, line, f"{value} has no 4.6 equivalent ({new})"))
                return
            self.put(name, value, new, new_value, line, f"renamed in {since}")
            return
        if self.table.get(name) is None and name not in self.table.all_names:
            raise TuneError(f"{self.tune.source}: {self.tune.where(line)}: unknown setting {shown(name)} (not a "
                            "Betaflight 4.6 setting, and not a 4.2-4.5 name aerobat translates)")
        self.put(name, value, name, value, line)

    def d_terms(self, settings: list[tuple[str, str, str, int]]) -> list[tuple[str, str, str, int]]:
        """Before 4.6, d_<axis> was the maximum D and d_min_<axis> the base: rewrite the pair for 4.6."""
        if not _older(self.tune.version, (4, 6)) and self.tune.version != (0, 0, 0):
            return settings
        rest = []
        pairs: dict[str, dict[str, tuple[str, int]]] = {}
        for section, name, value, line in settings:
            for axis in ("roll", "pitch", "yaw"):
                if name in (f"d_{axis}", f"d_min_{axis}"):
                    pairs.setdefault(axis, {})["min" if name.startswith("d_min") else "max"] = (value, line)
                    break
            else:
                rest.append((section, name, value, line))
        defaults = _D_DEFAULTS[(4, 2) if _older(self.tune.version, (4, 3)) else (4, 3)]
        for axis, pair in pairs.items():
            d_max = self.d_term(f"d_{axis}", *pair["max"]) if "max" in pair else defaults[axis][0]
            d_min = self.d_term(f"d_min_{axis}", *pair["min"]) if "min" in pair else defaults[axis][1]
            line = min(entry[1] for entry in pair.values())
            base = d_min if 0 < d_min < d_max else d_max
            why = (f"before 4.6 d_{axis} = {d_max} was the maximum D and d_min_{axis} = {d_min} the base "
                   f"({'active' if 0 < d_min < d_max else 'inactive: D stays d_' + axis}); a value the file does "
                   "not list is the writer's default")
            old = f"d_{axis},d_min_{axis}"
            self.put(old, f"{d_max},{d_min}", f"d_{axis}", str(base), line, why)
            self.put(old, f"{d_max},{d_min}", f"d_max_{axis}", str(d_max), line, why)
        return rest

    def d_term(self, name: str, value: str, line: int) -> int:
        """The integer a pre-4.6 D term is, in any range (:meth:`put` refuses one 4.6 does not take)."""
        number = parse_integer(value.strip(" "))
        if number is None:
            entry = self.table.get("d_roll")
            raise self.malformed(name, value, line, "not an integer as the firmware reads one (an optional sign and "
                                 f"decimal digits); {entry.allowed() if entry else 'allowed an integer'}")
        return number

    def command(self, word: str, args: str, line: int) -> None:
        if word == "feature":
            match = _FEATURE.fullmatch(args.strip())
            name = match.group(2).upper() if match else args.strip().lstrip("-").upper()
            if name == "AIRMODE":
                self.pinned.append(("feature AIRMODE", args, "flips need PID authority at zero throttle"))
            elif match and name in _FEATURES_APPLIED and name in self.table.features:
                self.features.append(f"feature {match.group(1)}{name}")
                self.applied.append((f"feature {name}", "off" if match.group(1) else "on", line))
            else:
                self.refused.append((f"feature {name}", args, line, "hardware feature (receiver, telemetry, OSD, "
                                     "LED, GPS, ...) or not in the SITL"))
        elif word in _PINNED_COMMANDS:
            self.pinned.append((word, args, _PINNED_COMMANDS[word]))
        elif word == "header":
            self.refused.append((args.partition(":")[0], "", line, _HARDWARE_COMMANDS["header"]))
        else:
            self.refused.append((word, args, line, _HARDWARE_COMMANDS.get(word, "hardware")))


def translate(tune: Tune, table: SitlTable | None = None) -> TuneReport:
    """The 4.6 commands for ``tune`` and the report (see the module docstring).

    Raises
    ------
    TuneError
        A setting no Betaflight version aerobat knows has, or a value that is no value of its setting's
        type as the firmware reads it (the message names the file, the line or header field, the
        setting and what it allows).
    """
    builder = _Builder(tune, table or load_table())
    settings = builder.d_terms(tune.active_settings())
    for section, name, value, line in settings:
        builder.setting(section, name, value, line)
    for word, args, line in tune.commands():
        builder.command(word, args, line)
    for section, index, name, value, line in tune.inactive_settings():
        active = tune.active_profile if section == "profile" else tune.active_rateprofile
        builder.refused.append((f"{section} {index}: {name}", value, line, f"not the active {section} ({active})"))
    for name, why in PINNED.items():
        if not any(entry[0] == name for entry in builder.pinned):
            builder.pinned.append((name, "", why))
    if tune.kind is TuneKind.CLI:
        builder.notes.append("settings the file does not list take Betaflight 4.6's defaults, which can differ "
                             "from the writer's (a 'dump' lists every setting)")
    if any(name.startswith("simplified_") for name in builder.sets):
        builder.notes.append("simplified-tuning sliders applied as settings; PIDs and filters as the file states "
                             "them (the firmware does not recompute them; aerobat never runs 'simplified_tuning "
                             "apply')")
    commands = tuple(builder.features) + tuple(f"set {n} = {v}" for n, v in builder.sets.items())
    return TuneReport(tune, tuple(builder.applied), tuple(builder.translated), tuple(builder.refused),
                      tuple(builder.pinned), commands, tuple(builder.notes))
