"""What the report shows, as data: per measurement, per history, the figures to draw.

:mod:`~pige_sym.report.gather` computes it, :mod:`~pige_sym.report.figures` draws it and
:mod:`~pige_sym.report.html` writes the page.  Units follow the kernels' ``UNITS`` (µm, µrad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pige_sym.compensation.parameters import AngleExtension
from pige_sym.compensation.study import CompensationStudyRow
from pige_sym.constants import VERSION as __version__
from pige_sym.diagnosis.diagnose import DiagnosisResult
from pige_sym.diagnosis.joint import JointDiagnosis
from pige_sym.files import json_ready
from pige_sym.identification.least_squares import METHODS
from pige_sym.identification.model_check import ModelCheck
from pige_sym.identification.result import IdentificationResult
from pige_sym.identification.studies import ProjectionStudy, SobolStudy
from pige_sym.kernels import load_kernels
from pige_sym.measurements.measurement import Measurement
from pige_sym.verdict.check import CheckResult

if TYPE_CHECKING:
    from pige_sym.verdict.compare import CompareResult



STUDIES = ("projection", "sobol")


SOBOL_EFFECT_UM = 15.0


PRIMARY_METHODS = (*METHODS, "diagnosis")


UNIT_TEXT = {"um": "µm", "urad": "µrad", "s": "s", "count": "count"}


@dataclass
class ReportFigure:
    """A PNG written for the report.

    Attributes
    ----------
    key : str
        What it shows (``deviation``, ``polar``, ``identification``, ``residual``,
        ``compensation``, ``sobol``).
    path : Path
        The PNG file.
    caption : str
        Plain text (escaped when rendered).
    """

    key: str
    path: Path
    caption: str


@dataclass
class Truth:
    """Known parameters of a simulated measurement (``<stem>.truth.json``).

    Attributes
    ----------
    path : Path
    values : dict of str to float
        Parameter name to value [µm or µrad]; parameters absent from the file are 0.
    notes : list of str
        What the sidecar holds that the report does not simulate (effects, outliers).
    extensions : list of AngleExtension
        Angle errors of the sidecar's effects (angular positioning, backlash) that the
        before/after simulates on the true machine.
    effects : list of dict
        The sidecar's effect records as written (``effect``, options, parameters).
    """

    path: Path
    values: dict[str, float]
    notes: list[str] = field(default_factory=list)
    extensions: list[AngleExtension] = field(default_factory=list)
    effects: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class MeasurementReport:
    """Everything the report shows about one measurement file.

    Attributes
    ----------
    path : Path
        The file as given.
    label : str
        Its directory name under the output directory (unique, file-system safe).
    measurement : Measurement
    machine : str
        Canonical machine code.
    identification : dict of str to IdentificationResult
        One result per method (``gauss-newton``, ``double-differential``).
    primary_method : {"gauss-newton", "double-differential", "diagnosis"}
        The estimate that drives the model overlay and the compensation.
    diagnosis : DiagnosisResult or None
        None when the diagnosis failed on these data (``diagnosis_error`` says why).
    compensation : list of CompensationStudyRow
        The measured trajectory first, then the NC program's poses when one is given.
    compensation_basis : {"truth", "model"}
        Whether "before" is simulated with the truth sidecar or with the identified model.
    not_compensated : list of str
        Parameters without a value, compensated as 0.
    extensions : list of AngleExtension
        Accepted diagnosis extensions compensated with the PIGEs (primary method ``diagnosis``).
    extensions_not_compensated : list of str
        Accepted extensions that are not compensated, with the reason.
    truth : Truth or None
    model_um : ndarray, shape=(n, 3) [µm] or None
        PIGE-model deviation of the primary estimate in the machine frame (None when a
        parameter is undetermined).
    compensated_program_text : str or None
        The NC program compensated with the primary estimate.
    compensated_program : Path or None
        Where :func:`write_report` wrote it (beside the figures).
    weighing : Weighing or None
        The values compensation enters, weighed by their uncertainty (:mod:`pige_sym.compensation.weighing`),
        judged on the NC program's poses when one is given, else on the measured poses.
    projection : ProjectionStudy or None
    sobol : SobolStudy or None
    figures : list of ReportFigure
    notes : list of str
    """

    path: Path
    label: str
    measurement: Measurement
    machine: str
    identification: dict[str, IdentificationResult]
    primary_method: str
    diagnosis: DiagnosisResult | None
    compensation: list[CompensationStudyRow]
    compensation_basis: str
    not_compensated: list[str]
    extensions: list[AngleExtension] = field(default_factory=list)
    extensions_not_compensated: list[str] = field(default_factory=list)
    truth: Truth | None = None
    diagnosis_error: str | None = None
    model_um: np.ndarray | None = None
    compensated_program_text: str | None = None
    compensated_program: Path | None = None
    projection: ProjectionStudy | None = None
    projection_noise_um: float | None = None
    sobol: SobolStudy | None = None
    sobol_ranges: dict[str, float] = field(default_factory=dict)
    sobol_same_as: int | None = None
    figures: list[ReportFigure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    check: CheckResult | None = None
    measured_at: str = ""
    time_source: str = ""
    model_check: ModelCheck | None = None  # of the Gauss–Newton PIGE-only fit (pige identify's)
    weighing: Any = None  # what compensation enters of the primary estimate (compensation.weighing.Weighing)
    compensation_result: Any = None  # the compensation stage's result (compensation.result.Compensation)

    @property
    def primary(self) -> IdentificationResult:
        """The result whose estimate is compensated (may hold extension parameters: diagnosis)."""
        if self.primary_method == "diagnosis" and self.diagnosis is not None:
            return self.diagnosis.final
        return self.identification[self.primary_method]

    def estimate(self) -> tuple[dict[str, float], list[str], np.ndarray | None]:
        """The primary estimate restricted to the machine's parameters.

        Returns
        -------
        values : dict of str to float
            Parameter to value [µm, µrad]; 0 where there is no value.
        missing : list of str
            Parameters without a value.
        covariance : ndarray, shape=(P, P) or None
            Their covariance (kernel parameter order); None when a value is missing.
        """
        res = self.primary
        params = set(load_kernels(self.machine).PARAMETERS)
        idx = [j for j, n in enumerate(res.parameters) if n in params]
        values = {res.parameters[j]: float(res.values[j]) for j in idx}
        missing = [k for k, v in values.items() if not math.isfinite(v)]
        cov = None if missing or res.covariance.shape[0] < len(idx) else res.covariance[np.ix_(idx, idx)]
        return {k: (v if math.isfinite(v) else 0.0) for k, v in values.items()}, missing, cov

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (non-finite numbers become ``None``)."""
        out: dict[str, Any] = {
            "file": str(self.path),
            "label": self.label,
            "machine": self.machine,
            "primary_method": self.primary_method,
            "identification": {k: v.to_dict() for k, v in self.identification.items()},
            "diagnosis": None if self.diagnosis is None else self.diagnosis.to_dict(),
            "diagnosis_error": self.diagnosis_error,
            "compensation": {"basis": self.compensation_basis, "not_compensated": self.not_compensated,
                             "rows": [r.to_dict() for r in self.compensation],
                             "program": None if self.compensated_program is None else str(self.compensated_program)},
            "truth": None if self.truth is None else {"file": str(self.truth.path), "pige": self.truth.values},
            "projection": None if self.projection is None else self.projection.to_dict(),
            "sobol": None if self.sobol is None else {**self.sobol.to_dict(), "half_ranges": self.sobol_ranges},
            "check": None if self.check is None else self.check.to_dict(),
            "model_check": None if self.model_check is None else self.model_check.to_dict(),
            "measured_at": self.measured_at, "time_source": self.time_source,
            "figures": [str(f.path) for f in self.figures],
            "notes": self.notes,
        }
        return json_ready(out)


@dataclass
class JointReport:
    """The joint section of one machine.

    Attributes
    ----------
    machine : str
        Canonical machine code.
    paths : list of Path
        The files, in the order given.
    diagnosis : JointDiagnosis
        Agreement, per-file parts and the joint PIGE estimate (``diagnosis.final``).
    check : CheckResult or None
        Verdict of the joint estimate (with ``--tolerances``).
    truth : dict of str to float or None
        True values [µm, µrad] when every file has a truth sidecar and they agree: the PIGEs and the
        parameters of the effects seen jointly (``<effect>.<parameter>``).
    curves : list of (str, ndarray, ndarray)
        Per ballbar file: label, measured ``dL`` and the final joint fit of it (with the effects seen
        jointly), shape=(n,) [µm].
    """

    machine: str
    paths: list[Path]
    diagnosis: JointDiagnosis
    check: CheckResult | None = None
    truth: dict[str, float] | None = None
    curves: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)  # ballbar: label, dL, fit [µm]

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "files": [str(p) for p in self.paths],
                "diagnosis": self.diagnosis.to_dict(),
                "check": None if self.check is None else self.check.to_dict(), "truth": self.truth}


@dataclass
class ReportData:
    """All the content of a report, before rendering.

    Attributes
    ----------
    measurements : list of MeasurementReport
    studies : tuple of str
        Studies requested (subset of ``projection``, ``sobol``).
    program : Path or None
        NC program compensated for every measurement.
    settings : dict of str to str
        Options the report was built with (shown in the header).
    created : str
        UTC time stamp (ISO 8601).
    html_path : Path or None
        Set by :func:`write_report`.
    """

    measurements: list[MeasurementReport]
    studies: tuple[str, ...] = ()
    program: Path | None = None
    settings: dict[str, str] = field(default_factory=dict)
    created: str = ""
    html_path: Path | None = None
    comparison: CompareResult | None = None
    history: HistoryData | None = None
    figures: list[ReportFigure] = field(default_factory=list)
    plan: Any = None  # a graded test plan (pige_sym.planning.Plan), shown by report.plan_section
    plan_html: str = ""
    joints: list[JointReport] = field(default_factory=list)  # joint sections (pige_sym.report.joint_section)
    maps: Any = None  # the error maps of the files (pige_sym.report.map_section.MapReport), with --map

    def to_dict(self) -> dict[str, Any]:
        return json_ready({
            "joint": [j.to_dict() for j in self.joints],
            "maps": None if self.maps is None else self.maps.to_dict(),
            "report": None if self.html_path is None else str(self.html_path),
            "created": self.created, "version": __version__, "settings": self.settings,
            "studies": list(self.studies), "program": None if self.program is None else str(self.program),
            "measurements": [m.to_dict() for m in self.measurements],
            "compare": None if self.comparison is None else self.comparison.to_dict(),
            "history": None if self.history is None else self.history.to_dict(),
        })


@dataclass
class HistoryData:
    """A machine's runs from the history database, for the trend plots.

    Attributes
    ----------
    machine_id : str
    database : str
        URL with the password hidden.
    runs : list of RunRecord
        In measurement order.
    comparisons : list of Comparison
        Consecutive runs.
    limits : dict of str to float
        Tolerance band per parameter [µm, µrad] (from ``--tolerances``, else the last run's check).
    check : CheckResult or None
        The last run judged against ``--tolerances`` (None without them: the verdict stored with the run).
    """

    machine_id: str
    database: str
    runs: list[Any]
    comparisons: list[Any]
    limits: dict[str, float] = field(default_factory=dict)
    check: CheckResult | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"machine_id": self.machine_id, "database": self.database, "runs": [r.to_dict() for r in self.runs],
                "comparisons": [c.to_dict() for c in self.comparisons], "limits": self.limits,
                "check": None if self.check is None else self.check.to_dict()}
