"""What adding healthy tests to a unit's baseline gives back
(:func:`condmon.workflows.monitoring.add_baseline_tests`): each record's
outcome, the baseline, and what an error part-way left stored."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError

if TYPE_CHECKING:
    from condmon.monitor.baseline import Baseline

__all__ = ["AddedTest", "BaselineAddResult", "say_what_was_stored"]


@dataclass(frozen=True)
class AddedTest:
    """One record offered to the baseline: stored, rejected, a duplicate or refused.

    ``refused`` records (a likely unit or sign error against the baseline so
    far) are not stored; their ``test_id`` is -1 and ``reason`` says why.
    ``warning`` is something to look at in a stored record (the same record
    already filed under another unit).
    """

    source: str
    test_id: int
    accepted: bool
    duplicate: bool
    reason: str | None = None
    refused: bool = False
    warning: str | None = None


@dataclass(frozen=True)
class BaselineAddResult:
    """Outcome of adding healthy tests.

    Attributes
    ----------
    tests : tuple of AddedTest
    baseline : Baseline or None
        The unit's baseline after the additions (None while fewer than 3
        accepted healthy tests exist).
    baseline_id : int or None
    message : str
    flags : tuple of dict
        Why the baseline may not be trustworthy (see
        :func:`condmon.monitor.assess_baseline`: an outlier, a trend in time
        order); empty when nothing is suspicious.
    notes : tuple of str
        What the user should know at once (a model monitored generically).
    units : dict of str to str
        Unit of each of the model's parameters (a regime's ``Tc@forward`` has
        ``Tc``'s); empty without a baseline.
    info : tuple of dict
        What is known of the baseline and is no warning: the parameters whose
        tests scatter more than their standard errors say (kind ``scatter``,
        see :func:`condmon.monitor.baseline.baseline_scatter`).
    """

    tests: tuple[AddedTest, ...]
    baseline: Baseline | None
    baseline_id: int | None
    message: str
    flags: tuple[dict[str, Any], ...] = ()
    notes: tuple[str, ...] = ()
    units: dict[str, str] = field(default_factory=dict)
    info: tuple[dict[str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result: each record's outcome, the baseline, the message,
        its flags, notes and what is known of it."""
        return {"tests": [dataclasses.asdict(t) for t in self.tests],
                "baseline": None if self.baseline is None else self.baseline.to_dict(),
                "baseline_id": self.baseline_id, "message": self.message,
                "flags": list(self.flags), "notes": list(self.notes),
                "units": dict(self.units), "info": list(self.info)}

    def _repr_html_(self) -> str:
        from condmon.report.notebook import html_table
        from condmon.report.tables import esc

        rows = [(t.source, t.test_id if t.test_id >= 0 else "—",
                 "refused" if t.refused else "already there" if t.duplicate else
                 "accepted" if t.accepted else "rejected", t.reason or "")
                for t in self.tests]
        warn = "".join(f"<p>warning: {esc(f.get('message', f))}</p>" for f in self.flags)
        return (f"<p>{esc(self.message)}</p>" + warn
                + html_table(["record", "test", "outcome", "reason"], rows))


def say_what_was_stored(err: CondmonError, i: int, n: int, added: Sequence[AddedTest],
                         unit: str) -> None:
    """Add to ``err`` (record ``i`` of ``n`` failed) what the records before it left
    in the history: a user must not take the failed command for one that stored nothing."""
    if n < 2 or not err.args or not isinstance(err.args[0], str):
        return
    stored = [t.source for t in added if t.test_id >= 0 and not t.duplicate]
    kept = (f"the {len(stored)} record(s) before it are stored as tests of {unit!r} "
            f"({', '.join(stored[:3])}{', ...' if len(stored) > 3 else ''}); mend or leave "
            "out this one and run the command again: the stored ones are skipped"
            if stored else "nothing was stored")
    err.args = (f"{err.args[0]} (record {i + 1} of {n}; {kept})", *err.args[1:])
