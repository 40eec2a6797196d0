"""Output-error (maximum-likelihood) estimator: SRIV start, then refinement.

See :mod:`condmon.identify.refine` for the criterion and the optimiser.
"""

from __future__ import annotations

import numpy as np  # noqa: F401  (used in the docstring example)
from numpy.typing import ArrayLike

from condmon._filter import lfilter  # noqa: F401  (used in the docstring example)
from condmon.errors import EstimationError
from condmon.identify._common import TFEstimate, prepare, to_model
from condmon.identify.closed_loop import noise_free_input
from condmon.identify.ls import _names, arx_theta, output_error_variance
from condmon.identify.refine import refine_output_error
from condmon.identify.sriv import sriv_iterations

__all__ = ["oe"]


def oe(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
       excitation: ArrayLike | None = None, outputs: tuple[str, ...] | None = None,
       input_name: str = "u") -> TFEstimate:
    """Output-error (maximum-likelihood) estimate, started from SRIV.

    Parameters
    ----------
    u, y, order, dt, outputs, input_name
        As for :func:`condmon.identify.sriv`.
    excitation : array_like, shape (N,) or (N, n_r), optional
        External excitation signals of a closed-loop test: they build the
        instruments of the SRIV start. The output-error criterion itself uses
        the measured input (the direct approach), which is consistent in
        closed loop when the sensor noise is white; the two-stage variant
        (simulating from the input part the excitation explains) carries the
        first stage's approximation error into the estimate, a bias of several
        percent on the reference rig.

    Returns
    -------
    TFEstimate
        ``method`` "oe"; ``path`` says where it started.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(4000)
    >>> y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u) + 0.2 * rng.standard_normal(4000)
    >>> est = oe(u, y, 2)
    >>> bool(np.allclose(est.theta, [-1.2, 0.5, 0.5, 0.2], atol=0.02)), est.path
    (True, 'sriv -> oe')
    """
    u_a, y_a = prepare(u, y, order)
    m = y_a.shape[1]
    closed = excitation is not None
    u_i = u_a if excitation is None else noise_free_input(u_a, excitation)
    try:
        start = sriv_iterations(u_a, y_a, order, u_i).theta
        path = "sriv -> oe"
    except EstimationError:
        start = arx_theta(u_a, y_a, order)
        path = "arx -> oe"
    fit = refine_output_error(u_a, y_a, order, start)
    notes = ["output error minimised from the " + path.split(" ")[0] + " estimate"]
    notes.append("output error on the measured input (direct approach)"
                 + ("; excitation used for the start's instruments" if closed else ""))
    if not fit.success:
        notes.append(f"output-error optimiser stopped at its cap ({fit.evaluations} evaluations)")
    return TFEstimate(to_model(fit.theta, order, dt, _names(outputs, m), input_name),
                      fit.theta, fit.covariance, output_error_variance(fit.theta, order, u_a, y_a),
                      "oe", iterations=fit.evaluations, converged=fit.success,
                      closed_loop_instruments=closed, n_samples=u_a.size,
                      notes=tuple(notes), path=path)
