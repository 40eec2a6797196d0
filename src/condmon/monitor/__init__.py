"""Monitoring: healthy baselines, percent change, fuzzy significant-change detection."""

from condmon.monitor.baseline import (
    MIN_BASELINE_TESTS, Baseline, BaselineChecks, assess_baseline, make_baseline, percent_change,
)
from condmon.monitor.fuzzy import (
    MonitorConfig, Symptoms, compute_symptoms, load_monitor_config, symptom_degree,
)

__all__ = ["Baseline", "make_baseline", "percent_change", "MIN_BASELINE_TESTS",
           "MonitorConfig", "load_monitor_config", "symptom_degree", "Symptoms",
           "compute_symptoms", "BaselineChecks", "assess_baseline"]
