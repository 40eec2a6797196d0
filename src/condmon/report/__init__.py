"""Reports: a fleet index and a page per unit, with figures of its history."""

from condmon.report.html import (
    FleetReport, ReportFiles, write_fleet_index, write_fleet_report, write_report,
)
from condmon.report.names import page_name

__all__ = ["write_report", "write_fleet_index", "write_fleet_report", "ReportFiles",
           "FleetReport", "page_name"]
