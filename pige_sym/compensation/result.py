"""The compensation stage's result: one object that ``pige compensate``, ``pige checkup`` and the report print from.

:func:`pige_sym.compensation.stage.compensate` computes it once (as ``scipy.optimize`` returns an
``OptimizeResult`` that every printer reads); nothing that renders it weighs, rewrites or predicts again.

What it holds:

- the **weighing** (:class:`~pige_sym.compensation.weighing.Weighing`): per value its estimate, standard error,
  the value entered and why, and the tool-point error each choice is predicted to leave, judged on the
  compensated program's poses or on the axes' travel;
- the **parameters as entered** (:class:`~pige_sym.compensation.parameters.CompensationParameters` holding the
  entered values): what every controller's entries and the NC rewrite are made from;
- the **program** (:class:`ProgramCorrection`): the corrected text, its change report and the compensated poses;
- the **controller** (:class:`ControllerEntries`): the printed entries, in sections a user pastes whole (or
  writes as files), the compensation tables they print (built once), and per way of entering them
  (:class:`EntryChoice`) exactly the values the printed lines carry, read from those tables, and the error they
  leave;
- **undetermined** values (no number in the parameter file) with why and what would determine them, and
  **advice** in plain words (:mod:`~pige_sym.compensation.advice`);
- for poses given without a program (the report's measured trajectory), the **corrected poses**.

JSON (:meth:`Compensation.to_dict`)::

    {"machine", "parameters_from", "judged_on", "weighing": {...}, "advice": [...],
     "undetermined": [{"name", "why", "remedy"}],
     "program": {"out"?, "report": {...}} | null,
     "controller": {"name", "choices": [{"label", "entered", "predicted_um"}], "not_representable",
                    "sections": [{"name", "file", "kind"}]} | null}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pige_sym.compensation.kinematics import CompensatedPoses
    from pige_sym.compensation.parameters import CompensationParameters
    from pige_sym.compensation.program import CompensationReport
    from pige_sym.compensation.weighing import ErrorPrediction, Weighing


@dataclass
class EntryChoice:
    """One way of entering the correction on a controller, and what it leaves.

    Attributes
    ----------
    label : str
        In words: ``the trt pins``, ``the trt pins and the COMP_FILEs``, ``pige's kinematics component``.
    values : dict of str to float
        Exactly what the printed lines carry, as they are printed (rounded to the table's unit), in the
        weighing's names (``EX0C``, ``C:ECC+@30``) [µm, µrad]; a value not named is not entered.
    predicted : ErrorPrediction or None
        The tool-point RMS error these entries leave over the judged poses (None without uncertainty).
    own : bool
        The controller's own entries (its kinematics, its tables); False for pige's kinematics component, which
        replaces the controller's kinematics (LinuxCNC).
    """

    label: str
    values: dict[str, float]
    predicted: ErrorPrediction | None = None
    own: bool = True

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "entered": dict(self.values), "own": self.own,
                "predicted_um": None if self.predicted is None else self.predicted.to_dict()}


@dataclass
class Section:
    """A part of the controller's output that is pasted whole into one file (or written as that file).

    Attributes
    ----------
    name : str
        What it is for, in words.
    file : str
        The file name ``--out-dir`` writes it as.
    kind : str
        ``hal``, ``ini``, ``comp`` (a LinuxCNC compensation file), ``text`` (any other controller's lines).
    text : str
    """

    name: str
    file: str
    kind: str
    text: str

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "file": self.file, "kind": self.kind}


@dataclass
class ControllerEntries:
    """A controller's entries of the correction (``pige compensate --controller NAME``).

    Attributes
    ----------
    name : str
    text : str
        Everything printed for the controller, comments included.
    sections : list of Section
        The same lines by target file (empty where the controller has one target).
    choices : list of EntryChoice
        Each way of entering, fewest values first.
    not_representable : list of str
        What no entry of this controller carries (only the NC rewrite compensates it).
    weighing : Weighing
        The values weighed over the axes' travel (the entries are judged there).
    entered_parameters : CompensationParameters
        The parameters holding those values: what the entries are made from.
    complete : ErrorPrediction or None
        The error left by every entered value (the NC rewrite).
    tables : list
        The controller's compensation tables (error maps) as built once by the stage: the printed lines and the
        values ``choices`` count are both read from them (LinuxCNC ``CompTable``, ISG ``SsfkList``, SINUMERIK
        ``LecTable``; empty for a controller without tables).
    """

    name: str
    text: str
    sections: list[Section]
    choices: list[EntryChoice]
    not_representable: list[str]
    weighing: Weighing
    entered_parameters: CompensationParameters
    complete: ErrorPrediction | None = None
    tables: list[Any] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "choices": [c.to_dict() for c in self.choices],
                "not_representable": list(self.not_representable), "sections": [s.to_dict() for s in self.sections],
                "predicted_complete_um": None if self.complete is None else self.complete.to_dict()}


@dataclass
class ProgramCorrection:
    """The corrected NC program: its text, the change report and the compensated poses of its changed blocks."""

    text: str
    report: CompensationReport
    poses: CompensatedPoses | None = None

    def to_dict(self) -> dict[str, Any]:
        return self.report.to_dict()


@dataclass
class Undetermined:
    """A value the parameter file gives no number: not entered, why, and what would determine it."""

    name: str
    why: str
    remedy: str

    def to_dict(self) -> dict[str, str]:
        return {"name": self.name, "why": self.why, "remedy": self.remedy}


@dataclass
class Compensation:
    """The compensation stage's result (module docstring)."""

    machine: str
    parameters_from: str
    weighing: Weighing
    entered_parameters: CompensationParameters
    program: ProgramCorrection | None = None
    controller: ControllerEntries | None = None
    undetermined: list[Undetermined] = field(default_factory=list)
    advice: list[str] = field(default_factory=list)
    poses: CompensatedPoses | None = None

    @property
    def text(self) -> str:
        """The corrected program (``program.text``)."""
        if self.program is None:
            raise AttributeError("no program was compensated")
        return self.program.text

    @property
    def report(self) -> CompensationReport:
        """The program's change report (``program.report``)."""
        if self.program is None:
            raise AttributeError("no program was compensated")
        return self.program.report

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "parameters_from": self.parameters_from,
                "judged_on": self.weighing.judged_on, "weighing": self.weighing.to_dict(),
                "advice": list(self.advice), "undetermined": [u.to_dict() for u in self.undetermined],
                "program": None if self.program is None else self.program.to_dict(),
                "controller": None if self.controller is None else self.controller.to_dict()}
