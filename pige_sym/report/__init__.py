"""The HTML calibration report (``pige report``): :mod:`.gather` computes, :mod:`.figures` draws,
:mod:`.html` writes one self-contained page."""

from pige_sym.report.data import PRIMARY_METHODS, MeasurementReport, ReportData
from pige_sym.report.gather import findings_text, gather_report
from pige_sym.report.html import build_report, render_html, write_report

__all__ = ["PRIMARY_METHODS", "MeasurementReport", "ReportData", "build_report", "findings_text", "gather_report",
           "render_html", "write_report"]
