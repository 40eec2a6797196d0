"""Which unknowns a record excites: identifiability from the route's sensitivities.

Before a route estimates, condmon asks which of the declared unknowns the
record's windows can tell apart. The question is answered on the route's own
sensitivity matrix ``S`` (rows: the weighted equations or outputs of the
route, columns: the unknowns; ``S[:, k]`` is the change of the weighted
residual for a *relative* change of unknown ``k``, so the columns compare):

- an unknown whose column is zero does not appear in the equations the route
  uses (an inertia in a steady balance);
- an unknown estimated alone with a relative standard error ``1/||S_k||``
  above ``max_relative_se`` is not excited enough;
- a set of unknowns is told apart when the collinearity index of its
  column-normalised sensitivities, ``γ = 1/σ_min`` (Brun, Reichert and Künsch
  2001), stays at or below ``max_collinearity`` (5 to 20 is usual) and each
  one's standard error in the set stays below ``max_relative_se``.

Unknowns are taken in the declaration's order (the first ones are preferred)
and kept while the set stays identifiable; the others are held at the unit's
baseline value or at nominal, and reported with the reason. The singular
values of the whole (normalised) matrix and the parameter directions they
span are reported too.

Written for condmon: the subset selection is a few lines of linear algebra
over the route's own matrices; no maintained package applies it to a
declared machine.

References
----------
.. [1] R. Brun, P. Reichert, H. R. Künsch, "Practical identifiability analysis
   of large environmental simulation models", Water Resources Research 37(4),
   2001.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.models.plausibility import IdentifiabilityLimits

__all__ = ["Identifiability", "IdentifiabilityLimits", "assess_identifiability",
           "all_identifiable", "dependence_at", "held_covariance", "HOLD_LEVEL", "hold_limit"]

FloatArray = NDArray[np.float64]

#: The level at which a held value the record contradicts is not held: a Wald
#: or likelihood-ratio statistic of the held unknowns beyond the chi-square
#: quantile (every route that holds an unknown tests it so).
HOLD_LEVEL = 0.01


def hold_limit(held: int, level: float = HOLD_LEVEL) -> float:
    """The chi-square quantile a held set's statistic is compared with:
    ``held`` degrees of freedom, ``level`` above it.

    Example
    -------
    >>> round(hold_limit(1), 3), round(hold_limit(2), 3)
    (6.635, 9.21)
    """
    if held == 1:   # the normal quantile squared, from the standard library: no scipy
        return NormalDist().inv_cdf(1.0 - level / 2.0) ** 2   # on a route's fast path
    from scipy.special import chdtri   # (scipy.special: half scipy.stats' import time)

    return float(chdtri(held, level))


@dataclass(frozen=True)
class Identifiability:
    """Which unknowns a record's windows excite, and why the others are held.

    Attributes
    ----------
    parameters : tuple of str
        The unknowns considered, in order of preference.
    identifiable : tuple of str
        Those estimated.
    reasons : dict of str to str
        Why each other unknown is not identifiable.
    singular_values : tuple of float
        Of the column-normalised sensitivity matrix of the unknowns that
        appear, largest first (one per such unknown). [-]
    directions : tuple of dict
        The parameter direction of each singular value (a right singular
        vector, ``{unknown: component}``); the last ones are the
        combinations the record cannot see. [-]
    relative_se : dict of str to float
        Each identifiable unknown's relative standard error in the estimated
        set (from the sensitivities, before the estimate), the record's noise
        taken as white and whatever else the route fits (the simulation
        route's initial states) as known: a screening figure, at or below the
        reported standard error over the value, never the error bar. [-]
    collinearity : float
        Collinearity index of the estimated set (1 for a single one; JSON
        ``collinearity_identified``; a reason gives the index of the set the
        unknown would have made). [-]
    limits : IdentifiabilityLimits
    dependence : dict of str to dict of str to float
        How each estimated unknown leans on each held one that appears in the
        route's equations: its relative change per relative change of the held
        value (``{estimated: {held: d ln estimated / d ln held}}``, the
        least-squares re-fit of the estimated set's sensitivities to the held
        one's; 0.5: the estimate moves by 5 % when the held value is 10 % off).
        Entries below 0.001 are left out. [-]
    held_uncertainty : dict of str to float
        Each held unknown's relative standard error in the record (the whole
        set's), where the route carried it into the estimated ones' standard
        errors (JSON ``held_relative_se``); a held one absent here fixes the
        others at its given value. [-]

    Example
    -------
    >>> S = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0]]) * 100
    >>> idf = assess_identifiability(S, ("Tc", "Tl", "J"))
    >>> idf.identifiable, idf.reasons["J"]
    (('Tc',), 'the equations the route uses do not contain it')
    >>> idf.reasons["Tl"][:31]
    'collinear with Tc (collinearity'
    """

    parameters: tuple[str, ...]
    identifiable: tuple[str, ...]
    reasons: dict[str, str] = field(default_factory=dict)
    singular_values: tuple[float, ...] = ()
    directions: tuple[dict[str, float], ...] = ()
    relative_se: dict[str, float] = field(default_factory=dict)
    collinearity: float = 1.0
    limits: IdentifiabilityLimits = IdentifiabilityLimits()
    dependence: dict[str, dict[str, float]] = field(default_factory=dict)
    held_uncertainty: dict[str, float] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """Whether every unknown is identifiable."""
        return len(self.identifiable) == len(self.parameters)

    @property
    def held(self) -> tuple[str, ...]:
        """The unknowns not identifiable (held), in order."""
        return tuple(p for p in self.parameters if p not in self.identifiable)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"identifiable": list(self.identifiable), "held": list(self.held),
                "reasons": dict(self.reasons),
                "singular_values": [float(s) for s in self.singular_values],
                "directions": [dict(d) for d in self.directions],
                "relative_se": {k: float(v) for k, v in self.relative_se.items()},
                "collinearity_identified": float(self.collinearity),
                "limits": {"max_collinearity": self.limits.max_collinearity,
                           "max_relative_se": self.limits.max_relative_se},
                "dependence": {k: dict(v) for k, v in self.dependence.items()},
                "held_relative_se": {k: float(v) for k, v in self.held_uncertainty.items()}}


def all_identifiable(parameters: Sequence[str]) -> Identifiability:
    """The answer for a route that estimates every unknown (nothing assessed)."""
    return Identifiability(tuple(parameters), tuple(parameters))


def _index(sv: FloatArray, columns: int) -> float:
    """The collinearity index of unit-norm sensitivities from their singular
    values (inf when fewer than the columns, or the smallest is ~0)."""
    if columns == 0:
        return 1.0
    smallest = float(sv[-1]) if sv.size >= columns else 0.0
    return float("inf") if smallest <= 1e-12 else 1.0 / smallest


def _design_index(design: FloatArray) -> float:
    """The collinearity index of ``design``'s columns (inf for a zero column)."""
    norms = np.sqrt(np.sum(design ** 2, axis=0))
    if design.shape[1] == 0 or not np.all(norms > 0.0):
        return float("inf") if design.shape[1] else 1.0
    return _index(np.linalg.svd(design / norms, compute_uv=False), design.shape[1])


def _whole_set(S: FloatArray, norms: FloatArray, lim: IdentifiabilityLimits,
               design: FloatArray | None = None
               ) -> tuple[FloatArray, float, FloatArray, FloatArray] | None:
    """The figures of the whole set of unknowns when together they pass
    every test, else None.

    The greedy choice below tries each unknown with those chosen before it.
    Dropping columns never lowers the smallest singular value of the
    unit-norm sensitivities (interlacing), nor raises a kept unknown's
    variance (a smaller model's ``diag((SᵀS)⁻¹)`` is at most the larger
    one's), so when the whole set passes, every trial passes and the choice
    is the whole set, with the figures of its last trial: this one SVD.
    """
    if S.shape[1] == 0 or not np.all(norms > 0.0):
        return None
    Sn = S / norms
    _, sv, vt = np.linalg.svd(Sn, full_matrices=False)
    gamma = _index(sv, S.shape[1]) if design is None else _design_index(design)
    if not gamma <= lim.max_collinearity:
        return None
    joint = np.sqrt(np.sum((vt / sv[:, None]) ** 2, axis=0)) / norms
    if not float(np.max(joint)) <= lim.max_relative_se:
        return None
    return joint, gamma, sv, vt


def assess_identifiability(sensitivity: ArrayLike, parameters: Sequence[str], *,
                           limits: IdentifiabilityLimits | None = None,
                           absent: Mapping[str, str] | None = None,
                           design: ArrayLike | None = None) -> Identifiability:
    """Choose the unknowns a route can estimate from its sensitivity matrix.

    Parameters
    ----------
    sensitivity : array_like, shape (n, p)
        Weighted sensitivities: column ``k`` is the change of the route's
        residuals (each divided by its noise standard deviation) for a
        relative change of unknown ``k`` (``X[:, k] * scale_k / sigma``). [-]
    parameters : sequence of str
        The unknowns, in the order they are preferred.
    limits : IdentifiabilityLimits, optional
    absent : mapping of str to str, optional
        Unknowns known not to enter the route's equations, with the reason
        (they are held whatever their column holds).
    design : array_like, shape (m, p), optional
        The same sensitivities with every row of an equation given one weight
        (the steady route's window means): the collinearity index is taken on
        it, the relative standard errors on ``sensitivity``. Whether the
        windows visited can tell two unknowns apart is a question of where
        they lie, not of their noise: one noisy window among two would
        otherwise make a Coulomb friction and a load torque "collinear"
        although a stroke each way separates them exactly; the noise is
        weighed by the relative standard error. None: both on ``sensitivity``.

    Returns
    -------
    Identifiability
    """
    lim = limits or IdentifiabilityLimits()
    names = tuple(parameters)
    S = np.atleast_2d(np.asarray(sensitivity, dtype=np.float64))
    if S.shape[1] != len(names):
        raise ValueError(f"{S.shape[1]} sensitivity columns for {len(names)} unknowns")
    S = np.where(np.isfinite(S), S, 0.0)
    norms = np.sqrt(np.sum(S ** 2, axis=0))
    reasons: dict[str, str] = {}
    chosen: list[int] = []
    kept: tuple[FloatArray, float, FloatArray, FloatArray] = (np.zeros(0), 1.0, np.zeros(0),
                                                             np.zeros((0, 0)))
    D = None if design is None else np.where(np.isfinite(d := np.atleast_2d(
        np.asarray(design, dtype=np.float64))), d, 0.0)
    whole = _whole_set(S, norms, lim, D) if not absent else None
    if whole is not None:   # every unknown passes together: so each prefix passes
        chosen, kept = list(range(len(names))), whole
    for k, name in enumerate(names if whole is None else ()):
        if absent and name in absent:
            reasons[name] = absent[name]
            continue
        if norms[k] <= 0.0:
            reasons[name] = "the equations the route uses do not contain it"
            continue
        alone = 1.0 / norms[k]
        if alone > lim.max_relative_se:
            reasons[name] = (f"not excited: estimated alone its relative standard error would "
                             f"be {100 * alone:.3g} % (limit {100 * lim.max_relative_se:g} %)")
            continue
        trial = [*chosen, k]
        Sn = S[:, trial] / norms[trial]
        # one SVD gives both the collinearity index (1 / the smallest singular
        # value) and the relative standard errors (diag((SnᵀSn)⁻¹)^½ / norms)
        _, sv_t, vt = np.linalg.svd(Sn, full_matrices=False)
        gamma = _index(sv_t, len(trial)) if D is None else _design_index(D[:, trial])
        if gamma > lim.max_collinearity:
            weak = np.abs(vt[-1])
            partners = [names[trial[i]] for i in np.argsort(-weak) if trial[i] != k
                        and weak[i] > 0.2 * weak.max()] or [names[trial[int(np.argmax(weak))]]]
            shown = "inf" if not np.isfinite(gamma) else f"{gamma:.3g}"
            reasons[name] = (f"collinear with {', '.join(partners)} (collinearity index "
                             f"{shown} > {lim.max_collinearity:g}): the windows used cannot "
                             "tell them apart")
            continue
        joint = np.sqrt(np.sum((vt / sv_t[:, None]) ** 2, axis=0)) / norms[trial]
        worst = int(np.argmax(joint))
        if joint[worst] > lim.max_relative_se:
            reasons[name] = (f"weakly excited together with {', '.join(names[i] for i in chosen)}"
                             f": the relative standard error of {names[trial[worst]]} would be "
                             f"{100 * joint[worst]:.3g} % (limit {100 * lim.max_relative_se:g} %)")
            continue
        chosen.append(k)
        kept = (joint, gamma, sv_t, vt)   # the chosen set's figures, as it stands
    present = [k for k in range(len(names)) if norms[k] > 0 and not (absent and names[k] in absent)]
    sv: tuple[float, ...] = ()
    dirs: tuple[dict[str, float], ...] = ()
    if present:
        if present == chosen:   # the last trial was this very matrix
            s_all, vt_all = kept[2], kept[3]
        else:
            _, s_all, vt_all = np.linalg.svd(S[:, present] / norms[present],
                                             full_matrices=False)
        sv = tuple(float(s) for s in s_all) + (0.0,) * (len(present) - s_all.size)
        dirs = tuple({names[present[j]]: x for j, x in enumerate(v)}   # (rounded at once:
                     for v in np.round(vt_all, 6).tolist())              # as np.round each)
    rse = dict(zip((names[k] for k in chosen), map(float, kept[0]))) if chosen else {}
    gamma_set = kept[1] if chosen else 1.0
    return Identifiability(names, tuple(names[k] for k in chosen), reasons, sv, dirs, rse,
                           gamma_set, lim, _dependence(S, names, chosen, present))


def dependence_at(sensitivity: ArrayLike, idf: Identifiability) -> dict[str, dict[str, float]]:
    """:attr:`Identifiability.dependence` from the route's sensitivities at
    another point: where the held values are held and the others re-fitted
    (the screening's point may lie far from it, and the lean with it).

    Example
    -------
    >>> S = np.array([[1.0, 1.0], [1.0, 1.0]]) * 100
    >>> dependence_at(S, assess_identifiability(S, ("Tc", "Tl")))
    {'Tc': {'Tl': -1.0}}
    """
    S = np.atleast_2d(np.asarray(sensitivity, dtype=np.float64))
    S = np.where(np.isfinite(S), S, 0.0)
    names = idf.parameters
    present = [k for k in range(len(names)) if float(np.abs(S[:, k]).sum()) > 0.0]
    chosen = [names.index(k) for k in idf.identifiable]
    return _dependence(S, names, chosen, present)


def _dependence(S: FloatArray, names: tuple[str, ...], chosen: list[int], present: list[int]
                ) -> dict[str, dict[str, float]]:
    """``{estimated: {held: d ln estimated / d ln held}}``: a held value off by
    a relative ``δ`` leaves the residuals the estimated set re-fits best by
    ``−(SₖᵀSₖ)⁻¹ Sₖᵀ Sₕ δ`` (the columns are per relative change)."""
    held = [h for h in present if h not in chosen]
    if not chosen or not held:
        return {}
    lean, *_ = np.linalg.lstsq(S[:, chosen], S[:, held], rcond=None)
    out: dict[str, dict[str, float]] = {}
    for i, k in enumerate(chosen):
        row = {names[h]: -float(lean[i, j]) for j, h in enumerate(held)
               if abs(lean[i, j]) >= 1e-3}
        if row:
            out[names[k]] = row
    return out


def held_covariance(S: FloatArray, scales: FloatArray, keep: list[int],
                    names: Sequence[str]) -> tuple[FloatArray, dict[str, float]] | None:
    """The estimated unknowns' covariance with the held ones' own uncertainty in
    the record carried, and each held one's relative standard error there
    (None: the record does not bound a held one, so only its given value fixes
    the others).

    A held unknown is one the user asked to estimate: its given value is a
    start, known only as well as the record knows it. The others lean on it
    (``L``, relative change per relative change), so their covariance is the
    held-fixed one plus ``L Σ Lᵀ``, ``Σ`` the held ones' covariance in the
    whole set (``S`` the whitened sensitivities per relative change of
    ``scales``; for small errors, the whole set's covariance, by the Schur
    complement). A lean is a derivative of logarithms, so a large relative
    error ``s`` is carried as the log-error ``ln(1 + s)``: a value known only
    to a factor of ten moves an estimate leaning on it by 0.003 by 0.7 %, not
    by 0.003 times 900 %.

    Example
    -------
    >>> S = np.array([[1.0, 0.5], [0.0, 1.0], [1.0, 0.0]])
    >>> cov, own = held_covariance(S, np.ones(2), [0], ("a", "b"))
    >>> round(own["b"], 3), bool(cov[0, 0] > 0.5)   # b to ±94 %, a's error bar widened
    (0.943, True)
    """
    if not np.all(np.isfinite(S)):
        return None
    _, sv, vt = np.linalg.svd(S, full_matrices=False)
    if not (sv.size and sv[-1] > 1e-9 * sv[0]):
        return None
    held = [i for i in range(len(names)) if i not in keep]
    rel = (vt.T / sv ** 2) @ vt   # (SᵀS)⁻¹ from the decomposition: no squared condition
    Sk, Sh = S[:, keep], S[:, held]
    fixed = np.linalg.pinv(Sk.T @ Sk)
    lean = -fixed @ (Sk.T @ Sh)
    sd = np.sqrt(np.maximum(np.diag(rel)[held], 0.0))
    shrink = np.where(sd > 0, np.log1p(sd) / np.where(sd > 0, sd, 1.0), 1.0)
    sigma = rel[np.ix_(held, held)] * np.outer(shrink, shrink)
    cov = (fixed + lean @ sigma @ lean.T) * np.outer(scales[keep], scales[keep])
    return cov, {names[h]: float(v) for h, v in zip(held, sd)}
