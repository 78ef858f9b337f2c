"""The set-up a measurement was taken with, as the machine history keeps it (``runs.setup_json``).

A check-up probes the sphere (or measures the R-test ball) where the last full calibration left it, with the
same stylus, pivots and axis sense; ``pige plan --checkup`` and ``pige program --checkup`` read all of it from
the history.  The record is a JSON object::

    {"instrument": "sphere-probe",              or "rtest"
     "machine": "wC'A'bXYZ(C1)t",
     "ball_mm": [100.0, 20.0, 60.0],            the sphere centre c(0) (probe: as fitted) or the R-test ball [mm]
     "pivots_mm": {"A": [0, 0, 0], ...},        nominal pivots of the rotary axes [mm]
     "tool_mm": null,                           head machines: stylus centre / ball from the last tool-side pivot
     "axis_sense": {"C": -1},                   axes commanded in the reverse of CONVENTIONS' sense (§9)
     "angle_range_deg": {"A": [-30, 0], ...},   the range of the measured poses (a check-up stays inside it)
     "noise_um": 0.28,                          probe: contact scatter; R-test: null (the run's RMS stands for it)
     "probe": {"sphere_radius_mm": 12.7, "stylus_radius_mm": 1.5, "kinematics": "identity",
               "program": {"dialect": "linuxcnc", "kinematics_codes": "off=M429 on=M428", "stylus_tool": "99",
                           "stylus_length_mm": "120", "work_offset": "G54 0, 0, 0", "window_mm": "0.3"}}}

``probe`` is null for an R-test.  The probing program's items are kept as its header wrote them
(:data:`~pige_sym.measurements.probe_import.PROGRAM_KEYS`); a probe file imported without ``--program`` has
none, and a check-up program then needs the controller options on the command line.

What a check-up re-measures (:func:`default_free`, :func:`parse_free`): by default the axis lines' positions, the
location errors in µm (thermal growth moves the axis lines; it hardly tilts them; Heidenhain's cycle 452 likewise
re-measures the positions only); the others are held at the last full calibration's values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pige_sym.errors import InputError
from pige_sym.measurements.measurement import Measurement

INSTRUMENTS = ("rtest", "sphere-probe")


@dataclass
class RunSetup:
    """The set-up of one measurement (module docstring); lengths [mm], angles [deg]."""

    instrument: str
    machine: str
    ball_mm: list[float]
    pivots_mm: dict[str, list[float]] = field(default_factory=dict)
    tool_mm: list[float] | None = None
    axis_sense: dict[str, int] = field(default_factory=dict)
    angle_range_deg: dict[str, list[float]] = field(default_factory=dict)
    noise_um: float | None = None
    probe: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"instrument": self.instrument, "machine": self.machine, "ball_mm": list(self.ball_mm),
                "pivots_mm": {a: list(v) for a, v in self.pivots_mm.items()}, "tool_mm": self.tool_mm,
                "axis_sense": dict(self.axis_sense), "angle_range_deg": dict(self.angle_range_deg),
                "noise_um": self.noise_um, "probe": self.probe}

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "the history") -> RunSetup:
        """The record as stored (checked: the instrument known, three numbers per point).

        Raises
        ------
        InputError
            A record that is not one (naming ``where``).
        """
        try:
            out = cls(str(data["instrument"]), str(data["machine"]), [float(x) for x in data["ball_mm"]],
                      {str(a): [float(x) for x in v] for a, v in (data.get("pivots_mm") or {}).items()},
                      None if data.get("tool_mm") is None else [float(x) for x in data["tool_mm"]],
                      {str(a): int(v) for a, v in (data.get("axis_sense") or {}).items()},
                      {str(a): [float(x) for x in v] for a, v in (data.get("angle_range_deg") or {}).items()},
                      None if data.get("noise_um") is None else float(data["noise_um"]), data.get("probe"))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: the stored set-up is incomplete ({exc})") from None
        points = [out.ball_mm, *out.pivots_mm.values(), *([] if out.tool_mm is None else [out.tool_mm])]
        if out.instrument not in INSTRUMENTS or any(len(p) != 3 or not all(map(math.isfinite, p)) for p in points):
            raise InputError(f"{where}: the stored set-up is not one pige wrote (instrument {out.instrument!r})")
        return out


def setup_of(m: Measurement) -> RunSetup:
    """The set-up of a measurement read by pige (R-test or probe file)."""
    instrument = m.metadata.get("instrument", "rtest")
    ranges = {a: [float(np.min(m.angles_deg[:, k])), float(np.max(m.angles_deg[:, k]))]
              for k, a in enumerate(m.rotary_axes)}
    probe = None
    noise = None
    if instrument == "sphere-probe":
        meta = m.metadata
        probe = {"sphere_radius_mm": _number(meta.get("sphere_radius_mm")),
                 "stylus_radius_mm": _number(meta.get("stylus_radius_mm")),
                 "kinematics": meta.get("probe_kinematics", "identity"),
                 "program": {k.removeprefix("program_"): v for k, v in meta.items() if k.startswith("program_")}}
        noise = _number(meta.get("contact_sigma_um"))
    return RunSetup(instrument, m.machine, [float(x) for x in m.ball_mm],
                    {a: [float(x) for x in v] for a, v in m.pivots_mm.items()},
                    None if m.tool_mm is None else [float(x) for x in m.tool_mm],
                    {a: int(v) for a, v in m.axis_sense.items() if int(v) == -1}, ranges, noise, probe)


def _number(text: str | None) -> float | None:
    """The leading number of a metadata value (``14.2 (fitted)`` → 14.2), None when there is none."""
    if text is None:
        return None
    try:
        x = float(text.split()[0])
    except (ValueError, IndexError):
        return None
    return x if math.isfinite(x) else None


def default_free(machine: str) -> list[str]:
    """The PIGEs a check-up re-measures by default: the location errors in µm (the axis lines' positions)."""
    from pige_sym.kernels import load_kernels

    kern = load_kernels(machine)
    return [n for n in kern.LOCATION_PARAMETERS if kern.UNITS[n] == "um"]


def parse_free(text: str | None, machine: str) -> list[str]:
    """``--pige EX0C,EY0C`` in the kernels' order (the letter O accepted for the digit zero), or the default (None).

    Raises
    ------
    InputError
        An empty list or item, a name given twice, or a name that is not a location PIGE of the machine.
    """
    from pige_sym.kernels import load_kernels
    from pige_sym.options import parse_names

    kern = load_kernels(machine)
    if text is None:
        return default_free(machine)
    zero = [n[:2] + "0" + n[3:] if len(n) >= 4 and n[0] == "E" and n[2] == "O" else n
            for n in (x.strip().upper() for x in text.split(","))]
    names = parse_names(",".join(zero), "--pige", "EX0C,EY0C")
    bad = [n for n in names if n not in kern.LOCATION_PARAMETERS]
    if bad or not names:
        raise InputError(f"--pige {text!r}: give location PIGEs of {kern.MACHINE_CODE} "
                         f"({', '.join(kern.LOCATION_PARAMETERS)})")
    return [n for n in kern.LOCATION_PARAMETERS if n in names]
