"""Diagnosis: fuzzy fault diagnoser over the parameter monitor's symptoms."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from condmon._lazy import load, names

if TYPE_CHECKING:
    from condmon.diagnose.diagnoser import STATUSES, Diagnosis, FaultDegree, diagnose
    from condmon.diagnose.evidence import CandidateSet, UnexplainedChange
    from condmon.diagnose.rules import RuleBase, load_rules, parse_condition
    from condmon.diagnose.structure_rules import RuleCheck, check_model_rules, check_rules

__all__ = ["Diagnosis", "FaultDegree", "diagnose", "STATUSES", "RuleBase", "load_rules",
           "parse_condition", "CandidateSet", "UnexplainedChange", "RuleCheck", "check_rules",
           "check_model_rules"]

# Imported on first use (PEP 562).
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("STATUSES", "Diagnosis", "FaultDegree", "diagnose"),
                    "condmon.diagnose.diagnoser"),
    **dict.fromkeys(("RuleBase", "load_rules", "parse_condition"), "condmon.diagnose.rules"),
    **dict.fromkeys(("CandidateSet", "UnexplainedChange"), "condmon.diagnose.evidence"),
    **dict.fromkeys(("RuleCheck", "check_rules", "check_model_rules"),
                    "condmon.diagnose.structure_rules"),
}


def __getattr__(name: str) -> Any:
    return load(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return names(globals(), _EXPORTS)
