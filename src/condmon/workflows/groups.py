"""Units among their peers: which units' own baselines lie outside their group's spread."""

from __future__ import annotations

from typing import Any

from condmon.monitor.generic import load_generic_settings
from condmon.monitor.group import unlike_group
from condmon.store.db import HistoryStore

__all__ = ["group_flags", "unit_rows"]


def group_flags(store: HistoryStore) -> dict[str, list[dict[str, Any]]]:
    """For every unit in a group with a baseline of its own, where that baseline
    lies outside its peers' between-unit spread (peers of the same model;
    see :func:`condmon.monitor.group.unlike_group`); units like their peers
    are left out."""
    settings = load_generic_settings()
    out: dict[str, list[dict[str, Any]]] = {}
    for group in store.groups():
        members = store.group_baselines(group)
        models = {u: store.unit_model(u) for u in members}
        for unit, own in members.items():
            peers = {u: b.baseline for u, b in members.items() if models[u] == models[unit]}
            flags = unlike_group(unit, own.baseline, peers, settings.group_flag_z,
                                 settings.group_min_units)
            if flags:
                out[unit] = [{**f, "group": group} for f in flags]
    return out


def unit_rows(store: HistoryStore) -> list[dict[str, Any]]:
    """:meth:`~condmon.store.HistoryStore.unit_summaries` with each unit's
    ``group`` and ``group_flags`` (its own baseline unlike its peers')."""
    flags = group_flags(store)
    return [{**r, "group_flags": flags.get(str(r["unit"]), [])} for r in store.unit_summaries()]
