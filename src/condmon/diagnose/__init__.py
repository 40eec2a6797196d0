"""Diagnosis: fuzzy fault diagnoser over the parameter monitor's symptoms."""

from condmon.diagnose.diagnoser import STATUSES, Diagnosis, FaultDegree, diagnose
from condmon.diagnose.rules import RuleBase, load_rules, parse_condition

__all__ = ["Diagnosis", "FaultDegree", "diagnose", "STATUSES", "RuleBase", "load_rules",
           "parse_condition"]
