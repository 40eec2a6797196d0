"""Reports: figures and an HTML page of a unit's history."""

from condmon.report.html import write_report

__all__ = ["write_report"]
