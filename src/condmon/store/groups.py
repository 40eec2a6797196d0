"""Groups of peer units: which units are judged together (part of :class:`HistoryStore`)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import sqlalchemy as sa

from condmon.store import schema as S
from condmon.store.base import StoreBase, check_name
from condmon.store.baselines import BaselinesMixin, StoredBaseline

__all__ = ["GroupsMixin"]


class GroupsMixin(BaselinesMixin, StoreBase):
    """A unit's group (``units.group_name``) and the baselines of a group's units."""

    def set_group(self, unit: str, group: str | None, *, model: str = "dc-motor",
                  model_source: str | None = None) -> bool:
        """Put ``unit`` in ``group`` (None: in none), creating the unit with
        ``model`` if it is new; returns whether anything changed (audited).

        Example
        -------
        >>> from condmon.store import open_store
        >>> with open_store("sqlite://") as store:
        ...     store.set_group("EMA-1", "line-A"), store.unit_group("EMA-1")
        (True, 'line-A')
        """
        if group is not None:
            check_name(group, "group name")

        def run(conn: sa.Connection) -> bool:
            uid = self.unit_id(unit, create=True, model=model, conn=conn,
                               model_source=model_source)
            before = conn.execute(sa.select(S.units.c.group_name)
                                  .where(S.units.c.id == uid)).scalar()
            if before == group:
                return False
            conn.execute(sa.update(S.units).where(S.units.c.id == uid).values(group_name=group))
            self._log(conn, "group set", unit_id=uid,
                      detail={"unit": unit, "group": group, "before": before})
            return True

        return self._write(run, lock=unit)

    def unit_group(self, unit: str) -> str | None:
        """The unit's group (None: none, or an unknown unit)."""
        row = self._read(lambda c: c.execute(sa.select(S.units.c.group_name)
                                             .where(S.units.c.name == unit)).first())
        return None if row is None or row[0] is None else str(row[0])

    def groups(self) -> dict[str, list[str]]:
        """Every group with its units (by name)."""
        rows = self._read(lambda c: c.execute(
            sa.select(S.units.c.group_name, S.units.c.name)
            .where(S.units.c.group_name.is_not(None))
            .order_by(S.units.c.group_name, S.units.c.name)).all())
        out: dict[str, list[str]] = {}
        for group, name in rows:
            out.setdefault(str(group), []).append(str(name))
        return out

    def group_baselines(self, group: str) -> dict[str, StoredBaseline]:
        """The latest version of each of the group's units' active baseline
        (units without one are left out)."""
        out: dict[str, StoredBaseline] = {}
        for unit in self.groups().get(group, []):
            latest = self.latest_baseline(unit)
            if latest is not None:
                out[unit] = latest
        return out

    def group_flags(self, groups: Iterable[str] | None = None
                    ) -> dict[str, list[dict[str, Any]]]:
        """For every unit in a group (of ``groups``, default all) with a baseline of its own, where that
        baseline lies outside its peers' between-unit spread (peers of the same
        model; see :func:`condmon.monitor.group.unlike_group`, limits in
        ``condmon/data/generic-monitor.toml``); units like their peers are left out."""
        from condmon.monitor.generic import load_generic_settings
        from condmon.monitor.group import unlike_group

        settings = load_generic_settings()
        out: dict[str, list[dict[str, Any]]] = {}
        wanted = None if groups is None else set(groups)
        for group in self.groups():
            if wanted is not None and group not in wanted:
                continue
            members = self.group_baselines(group)
            models = {u: self.unit_model(u) for u in members}
            for unit, own in members.items():
                peers = {u: b.baseline for u, b in members.items() if models[u] == models[unit]}
                flags = unlike_group(unit, own.baseline, peers, settings.group_flag_z,
                                     settings.group_min_units)
                if flags:
                    out[unit] = [{**f, "group": group} for f in flags]
        return out
