"""Identification: discrete transfer-function estimators, fit check, the estimate pipeline.

Estimators share their leading arguments ``(u, y, order, *, dt, ...)``:

- :func:`arx` — least squares (biased by output noise; a baseline).
- :func:`iv` — basic instrumental variables.
- :func:`sriv` — simplified refined IV (Young): the default; falls back to the
  output-error refinement when its iterations fail.
- :func:`oe` — output error (maximum likelihood), started from SRIV.
- :func:`rls`, :func:`riv` — recursive LS / IV with a prior.

Closed-loop data: pass the external excitation signals as ``excitation`` and the
instruments are built from them (:func:`noise_free_input`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from condmon._lazy import load, names, shield

if TYPE_CHECKING:
    from condmon.identify._common import TFEstimate
    from condmon.identify.closed_loop import noise_free_input
    from condmon.identify.estimate import (
        DEFAULT_EXCITATION, EstimateResult, estimate, estimate_joint, estimate_record,
        list_estimators,
    )
    from condmon.identify.fit import DEFAULT_FIT_THRESHOLD, FitCheck, fit_check
    from condmon.identify.ls import arx, iv
    from condmon.identify.oe import oe
    from condmon.identify.refine import OutputErrorFit, refine_output_error
    from condmon.identify.recursive import RecursiveEstimate, riv, rls
    from condmon.identify.sriv import sriv

__all__ = [
    "TFEstimate", "RecursiveEstimate", "EstimateResult", "FitCheck",
    "arx", "iv", "sriv", "oe", "rls", "riv", "noise_free_input",
    "OutputErrorFit", "refine_output_error",
    "fit_check", "DEFAULT_FIT_THRESHOLD", "estimate", "estimate_record", "estimate_joint",
    "list_estimators", "DEFAULT_EXCITATION",
]

# Imported on first use (PEP 562): the command line's help needs none of them.
_EXPORTS = {
    "TFEstimate": "condmon.identify._common",
    "noise_free_input": "condmon.identify.closed_loop",
    **dict.fromkeys(("DEFAULT_EXCITATION", "EstimateResult", "estimate", "estimate_joint",
                     "estimate_record", "list_estimators"), "condmon.identify.estimate"),
    **dict.fromkeys(("DEFAULT_FIT_THRESHOLD", "FitCheck", "fit_check"), "condmon.identify.fit"),
    "arx": "condmon.identify.ls", "iv": "condmon.identify.ls",
    "oe": "condmon.identify.oe",
    "OutputErrorFit": "condmon.identify.refine", "refine_output_error": "condmon.identify.refine",
    **dict.fromkeys(("RecursiveEstimate", "riv", "rls"), "condmon.identify.recursive"),
    "sriv": "condmon.identify.sriv",
}

# The functions estimate, oe and sriv share their names with their modules.
shield(__name__, ("estimate", "oe", "sriv"))


def __getattr__(name: str) -> Any:
    return load(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return names(globals(), _EXPORTS)
