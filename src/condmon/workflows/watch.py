"""Live monitoring: each unit's stream handled as it arrives, events out.

:class:`Watcher` is the transport-free heart of ``condmon watch``: it takes
validated chunks (:class:`~condmon.io.stream.Chunk`, from MQTT or any source),
and for each unit:

- a **plant-model unit** (a declaration with no ``[estimation]``, e.g. ``hst``)
  is tracked online (:class:`~condmon.diagnose.tracking.ModelTracker`: the model
  beside the stream, residuals, debounced detection). A detection is an event
  at once; the isolation starts (in a worker thread, the stream going on) once
  ``isolate_after`` seconds of data have followed it, on the samples kept since
  the unit's stream (re)started, and is stored as ``isolate --unit`` stores it;
- an **estimation-model unit** (``dc-motor``, a declaration with
  ``[estimation]``) collects its test's chunks until ``{"end": true}``; the
  record is then checked as by ``condmon check`` (or, while the unit has no
  baseline, added to it as by ``condmon baseline add``).

Every status change is an event (:class:`WatchEvent`), handed to ``publish``
(the MQTT transport publishes it retained on ``condmon/<unit>/status``).
Counters say what was received, refused, dropped and stored.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np
import pandas as pd

from condmon.diagnose.isolation import IsolationResult, IsolationSettings, isolate
from condmon.diagnose.online import OnlineDetection
from condmon.diagnose.checks import check_stream_chunk
from condmon.diagnose.tracking import ChunkOutcome, ModelTracker, measured_start, started_at
from condmon.errors import CondmonError, DataError
from condmon.io.stream import Chunk, StreamLimits
from condmon.models.machine import Machine
from condmon.models.registry import get_model
from condmon.store.db import HistoryStore
from condmon.store.engine import StoreError
from condmon.store.history import DuplicateTestError
from condmon.workflows.cycles import record_by_record
from condmon.workflows.watch_bounds import Bounds, Refused, by_length, nbytes, pieces

__all__ = ["WatchEvent", "WatchCounters", "Watcher"]


@dataclass(frozen=True)
class WatchEvent:
    """A unit's status change or detection, as published.

    Attributes
    ----------
    unit : str
    status : str
        ``go``, ``advisory``, ``no-go`` or ``retest``.
    time : str
        When the event was made, ISO 8601 UTC (wall clock).
    reason : str
        What happened, in one line.
    isolated : tuple of str
        The parameters isolated (plant-model units), else empty.
    kind : str
        ``watching``, ``detected``, ``isolated``, ``checked`` or ``baseline``.
    stream_time : float or None
        The stream's time of the event (a detection's sample). [s]
    """

    unit: str
    status: str
    time: str
    reason: str
    isolated: tuple[str, ...] = ()
    kind: str = "watching"
    stream_time: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The published JSON object."""
        return {"unit": self.unit, "status": self.status, "time": self.time,
                "reason": self.reason, "isolated": list(self.isolated), "kind": self.kind,
                "t": self.stream_time}


@dataclass
class WatchCounters:
    """What a watcher has seen (each a count)."""

    received: int = 0
    samples: int = 0
    refused: int = 0
    dropped: int = 0
    detections: int = 0
    isolations: int = 0
    checks: int = 0
    events: int = 0

    def to_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


@dataclass
class _Plant:
    """A plant-model unit's stream since it (re)started."""

    chunks: list[dict[str, np.ndarray]] = field(default_factory=list)
    refs: list[int | None] = field(default_factory=list)  # each kept chunk's journal row
    first_t: float = math.nan  # the stream time the model was started at [s]
    detection: OnlineDetection | None = None
    pending: cf.Future[IsolationResult] | None = None
    isolated: bool = False
    said: set[str] = field(default_factory=set)


@dataclass
class Watcher:
    """Handle every unit's chunks; see the module's description.

    Parameters
    ----------
    store : HistoryStore
    model : str, optional
        The model of units new to the history (known units keep their own).
    settings : IsolationSettings, optional
        Detection, estimation and isolation settings (default: shipped).
    publish : callable, optional
        Called with every event (default: nothing).
    log : callable, optional
        Called with every line worth logging (default: nothing).
    isolate_after : float, optional
        Seconds of data after a detection before the isolation starts (default:
        what the isolation needs, the longer of the estimation's settle plus
        its shortest window and the comparison's settle, plus 1 s). [s]
    keep : float, optional
        Seconds of a plant unit's stream kept before a detection, for its
        isolation (which starts its model from the kept record's first
        readings); after a detection everything is kept until the isolation
        (default: ``[stream] keep`` of ``limits.toml``, 60 s: 190 kB a unit at
        100 Hz with four columns). [s]
    bounds : Bounds, optional
        Units admitted and bytes held (default: ``[stream]`` of ``limits.toml``,
        every unit name).
    """

    store: HistoryStore
    model: str | None = None
    settings: IsolationSettings = field(default_factory=IsolationSettings.load)
    publish: Callable[[WatchEvent], None] = lambda event: None
    log: Callable[[str], None] = lambda line: None
    isolate_after: float | None = None
    keep: float = field(default_factory=lambda: StreamLimits.shipped().keep)
    max_test_samples: int = field(
        default_factory=lambda: StreamLimits.shipped().max_test_samples)
    bounds: Bounds = field(default_factory=Bounds)
    #: Set to stop within one step: chunks not yet stepped stay in the journal.
    halt: threading.Event = field(default_factory=threading.Event)
    counters: WatchCounters = field(default_factory=WatchCounters)
    #: Journal rows of chunks done with (effect stored, refused, or out of the
    #: kept window): the transport deletes them (:mod:`condmon.store.journal`).
    finished: list[int] = field(default_factory=list)
    _trackers: dict[str, ModelTracker] = field(default_factory=dict, repr=False)
    _plants: dict[str, _Plant] = field(default_factory=dict, repr=False)
    _tests: dict[str, list[dict[str, np.ndarray]]] = field(default_factory=dict, repr=False)
    _test_refs: dict[str, list[int]] = field(default_factory=dict, repr=False)
    _status: dict[str, str] = field(default_factory=dict, repr=False)
    _machines: dict[str, tuple[str, Machine]] = field(default_factory=dict, repr=False)
    _pool: cf.ThreadPoolExecutor = field(
        # one isolation at a time: scipy's LSODA (before 1.15) keeps state per process
        default_factory=lambda: cf.ThreadPoolExecutor(1, thread_name_prefix="isolate"),
        repr=False)

    def machine_of(self, unit: str) -> tuple[str, Machine]:
        """The unit's model (its own if the history knows it, else ``model``)."""
        if unit not in self._machines:
            name = self.store.unit_model(unit) or self.model
            if name is None:
                raise DataError(f"unit {unit!r} is new to the history and no model was given "
                                "(watch --model NAME|FILE)")
            self._machines[unit] = (name, get_model(name))
            said = record_by_record(name, "streamed test (up to its {\"end\": true})")
            if said:   # (once per unit and watch)
                self.log(f"{unit}: {said}")
        return self._machines[unit]

    def handle(self, chunk: Chunk) -> list[WatchEvent]:
        """Take one validated chunk; the events it causes."""
        return self.handle_many([chunk])

    def handle_many(self, chunks: Sequence[Chunk]) -> list[WatchEvent]:
        """Take validated chunks in arrival order; the events they cause.

        The chunks of plant-model units are fed to their model's tracker
        together (one chunk per unit per round), so many units cost one
        vectorised integration.
        """
        events: list[WatchEvent] = []
        rounds: dict[str, list[dict[str, Chunk]]] = {}
        models: dict[str, Machine] = {}
        for chunk in chunks:
            self.counters.received += 1
            self.counters.samples += chunk.samples
            try:
                self.bounds.admit(chunk.unit)
                name, machine = self.machine_of(chunk.unit)
                if machine.spec.unknowns:
                    events += self._test_chunk(chunk, name)
                    continue
                if not chunk.columns:
                    self._finish(chunk.ref)
                    continue
                missing = [s for s in machine.plant.sensor_names if s not in chunk.columns]
                if missing:
                    raise DataError(
                        f"unit {chunk.unit!r}: the chunk has no column "
                        f"{', '.join(map(repr, missing))}; model {machine.name!r} needs t, "
                        f"{', '.join(machine.plant.sensor_names)}")
                check_stream_chunk(machine.plant, chunk.columns, f"unit {chunk.unit!r}",
                                   self.settings.record)
            except StoreError:
                raise  # the history is out of reach: the journal keeps the message
            except Exception as exc:  # one message never takes the watcher down
                self._refuse([chunk], exc)
                continue
            models[name] = machine
            queue = rounds.setdefault(name, [])
            at = next((k for k, r in enumerate(queue) if chunk.unit not in r), len(queue))
            for k, piece in enumerate(pieces(chunk), start=at):
                while len(queue) <= k:
                    queue.append({})
                queue[k][chunk.unit] = piece
        for name, queue in rounds.items():
            machine = models[name]  # the unit's, as machine_of found it (no file read again)
            tracker = self._trackers.get(name)
            if tracker is None:
                tracker = self._trackers[name] = ModelTracker(machine.plant,
                                                              self.settings.detection)
            for batch in (g for r in queue for g in by_length(list(r.values()))):
                if self.halt.is_set():
                    return events  # a stop: what is left stays in the journal
                try:
                    outs = tracker.feed({c.unit: c.columns for c in batch})
                except Exception as exc:  # one batch's model step never stops the stream
                    self._refuse(batch, exc)
                    continue
                for chunk, out in zip(batch, outs):
                    try:
                        events += self._tracked(chunk, out, machine)
                    except StoreError:
                        raise
                    except Exception as exc:  # one chunk's outcome never stops the stream
                        self._refuse([chunk], exc)
        return events

    def _refuse(self, chunks: Sequence[Chunk], exc: BaseException) -> None:
        """Count and say a refusal in one line; the chunks are done with."""
        self.counters.refused += len(chunks)
        what = str(exc) if isinstance(exc, CondmonError) else (
            f"unit {chunks[0].unit!r}: {type(exc).__name__}: {str(exc)[:200]}")
        if not isinstance(exc, Refused) or exc.say:
            self.log(f"refused: {what}")
        for chunk in chunks:
            self._finish(chunk.ref)

    def _finish(self, *refs: int | None) -> None:
        self.finished.extend(r for r in refs if r is not None)

    def poll(self, wait: bool = False) -> list[WatchEvent]:
        """Isolations finished since the last call, stored; their events."""
        events = []
        for unit, plant in self._plants.items():
            fut = plant.pending
            if fut is None or not (wait or fut.done()):
                continue
            plant.pending = None
            try:
                res = fut.result()
            except Exception as exc:  # an isolation's failure is said; the stream goes on
                self.log(f"{unit}: isolation failed: {exc}")
                plant.isolated = True
                self._trim(plant, unit)
                continue
            events += self._isolated(unit, res, plant)
        return events

    def close(self) -> list[WatchEvent]:
        """Finish pending isolations (stored), isolate a detection whose data
        has not all arrived on what there is (so it is kept), say what tests
        were left unfinished, and stop the workers."""
        for unit, plant in self._plants.items():
            if plant.detection is not None and not plant.isolated and plant.pending is None:
                name, machine = self.machine_of(unit)
                self.log(f"{unit}: stopping before the isolation's data arrived: isolating "
                         "on what there is, so the detection is kept")
                plant.pending = self._submit(unit, plant, machine)
        events = self.poll(wait=True)
        for unit, parts in self._tests.items():
            if parts:
                kept = ("; it is kept in the journal and goes on at the next start"
                        if self._test_refs.get(unit) else "")
                self.log(f"{unit}: an unfinished test ({sum(len(p['t']) for p in parts)} "
                         "samples, no {\"end\": true}) was not checked" + kept)
        self._pool.shutdown(wait=True)
        return events

    # -- plant-model units --------------------------------------------------------

    def _tracked(self, chunk: Chunk, out: ChunkOutcome, machine: Machine) -> list[WatchEvent]:
        """What one tracked chunk means: notes, the first status, a detection, and
        the isolation started once enough data has followed the detection."""
        plant = self._plants.setdefault(chunk.unit, _Plant())
        events: list[WatchEvent] = []
        if out.dropped is not None:
            self.counters.dropped += 1
            self.log(f"{chunk.unit}: chunk dropped, {out.dropped}")
            self._finish(chunk.ref)
            return events
        for note in out.notes:
            if note not in plant.said:
                self.log(f"{chunk.unit}: {note}")
            if note.startswith("input "):
                plant.said.add(note)  # said once per unit, not at every chunk
        if out.dropped is None and (not plant.chunks
                                    or any("started again" in n for n in out.notes)):
            self._finish(*plant.refs)
            self.bounds.give(chunk.unit, sum(nbytes(c) for c in plant.chunks))
            plant.chunks, plant.refs, plant.detection, plant.isolated = [], [], None, False
            plant.first_t = float(chunk.columns["t"][0])
        self.bounds.take(chunk.unit, nbytes(chunk.columns))
        plant.chunks.append(chunk.columns)
        plant.refs.append(chunk.ref)
        self._trim(plant, chunk.unit)
        if self._status.get(chunk.unit) is None:
            # the unit is in the history from its first chunk (the fleet page lists it)
            self.store.unit_id(chunk.unit, create=True, model=machine.name,
                               model_source=machine.origin)
            events.append(self._event(chunk.unit, "go", "watching: the model runs beside the "
                                      "stream", "watching"))
        if out.detection is not None:
            d = out.detection
            plant.detection = d
            earlier = self._continuing(chunk.unit, d, plant)
            if earlier is not None:
                plant.isolated = True  # the stored isolation holds; the window is trimmed again
                self.log(f"{chunk.unit}: the fault of isolation i{earlier} is still there at "
                         f"t = {plant.first_t:g} s, where the model was started; not isolated "
                         "again")
                events.append(self._event(
                    chunk.unit, "no-go", f"the fault of isolation i{earlier} is still there "
                    f"(the model started at t = {plant.first_t:g} s on a faulty unit)",
                    "detected", stream_time=d.time))
                return events
            self.counters.detections += 1
            events.append(self._event(
                chunk.unit, "no-go", f"fault detected at t = {d.time:g} s: "
                f"{', '.join(d.fired)} outside the band since t = {d.onset:g} s",
                "detected", stream_time=d.time))
        s = self.settings
        after = self.isolate_after if self.isolate_after is not None else 1.0 + max(
            s.estimation_settle + s.min_window, s.compare_settle)
        if (plant.detection is not None and not plant.isolated and plant.pending is None
                and out.end >= plant.detection.time + after):
            plant.pending = self._submit(chunk.unit, plant, machine)
        return events

    def _submit(self, unit: str, plant: _Plant, machine: Machine) -> cf.Future[IsolationResult]:
        """Start the isolation of the kept record, the model started where it starts
        (as the online one did)."""
        record = self._record(plant)
        first = {c: record[c].to_numpy()[:1] for c in record.columns}
        model = started_at(machine.plant, measured_start(machine.plant, first))
        return self._pool.submit(isolate, record, model, settings=self.settings, workers=1,
                                 source=f"{unit} stream")

    def _trim(self, plant: _Plant, unit: str) -> None:
        """Keep the last ``keep`` seconds, and whatever follows a detection until
        its isolation is done; never more than ``[stream] unit_bytes``."""
        while len(plant.chunks) > 1:
            span = plant.chunks[-1]["t"][-1] - plant.chunks[1]["t"][0]
            loose = plant.detection is None or plant.isolated
            if not self.bounds.over_unit(unit) and (span < self.keep or not loose):
                break
            if not loose and not plant.said.intersection({"bytes"}):
                plant.said.add("bytes")
                self.log(f"{unit}: the record kept for the isolation passes [stream] "
                         "unit_bytes; its oldest samples are let go")
            self.bounds.give(unit, nbytes(plant.chunks.pop(0)))
            self._finish(plant.refs.pop(0))

    @staticmethod
    def _record(plant: _Plant) -> pd.DataFrame:
        cols = plant.chunks[0].keys()
        return pd.DataFrame({c: np.concatenate([ch[c] for ch in plant.chunks if c in ch])
                             for c in cols})

    def _isolated(self, unit: str, res: IsolationResult, plant: _Plant) -> list[WatchEvent]:
        from condmon.workflows.isolation import StoredIsolation, store_isolation

        plant.isolated = True
        record = self._record(plant)
        self._trim(plant, unit)
        record.attrs["source"] = f"{unit} stream"
        name, _ = self.machine_of(unit)
        earlier = self._stored_detection(unit, res)
        if earlier is not None:  # a restart re-sent the stream: the same detection, kept once
            self.log(f"{unit}: this detection is isolation i{earlier} already; not stored again")
            kept = StoredIsolation(unit, earlier, True, None)
        else:
            kept = store_isolation(self.store, unit, res, record, None, name)
        self.counters.isolations += 0 if kept.duplicate else 1
        plain = len(res.isolated) == 1 and not res.sensor_faults
        what = ("isolated: " + res.isolated[0] if plain else
                res.statement or ("isolated: " + ", ".join(res.isolated) if res.isolated
                                  else "not isolated"))
        return [self._event(unit, "no-go", f"{what} (isolation i{kept.isolation_id}"
                            + (", already stored" if kept.duplicate else "") + ")",
                            "isolated", tuple(res.isolated),
                            plant.detection.time if plant.detection else None)]

    def _continuing(self, unit: str, d: OnlineDetection, plant: _Plant) -> int | None:
        """The stored isolation of this unit's stream whose fault a model started
        on an already faulty unit detects again (after a restart of the watcher:
        the detection's onset is where the model started, and the stored
        detection is earlier), if any."""
        tol = 2.0 * self.settings.detection.persistence + 1.0
        if not math.isfinite(plant.first_t) or d.onset > plant.first_t + tol:
            return None
        iso = self.store.isolations(unit)
        if not len(iso):
            return None
        before = iso[(iso["source"] == f"{unit} stream")
                     & (iso["detection_time"] <= d.onset + tol)]
        return int(before.index[-1]) if len(before) else None

    def _stored_detection(self, unit: str, res: IsolationResult) -> int | None:
        """The stored isolation of the same stream detection (within twice the
        persistence and a second of stream time), if any."""
        if res.detection_time is None:
            return None
        iso = self.store.isolations(unit)
        if not len(iso):
            return None
        tol = 2.0 * self.settings.detection.persistence + 1.0
        same = iso[(iso["source"] == f"{unit} stream")
                   & ((iso["detection_time"] - res.detection_time).abs() <= tol)]
        return int(same.index[0]) if len(same) else None

    # -- estimation-model units: whole tests ---------------------------------------

    def _test_chunk(self, chunk: Chunk, name: str) -> list[WatchEvent]:
        parts = self._tests.setdefault(chunk.unit, [])
        refs = self._test_refs.setdefault(chunk.unit, [])
        if chunk.columns:
            held = sum(len(p["t"]) for p in parts)
            if parts and set(chunk.columns) != set(parts[0]):
                raise DataError(f"unit {chunk.unit!r}: the chunk's columns "
                                f"{sorted(chunk.columns)} are not the test's "
                                f"{sorted(parts[0])}; chunk refused")
            size = nbytes(chunk.columns)
            if self.bounds.over_unit(chunk.unit, size):
                self._drop_test(chunk.unit)
                raise self.bounds.refusal(
                    "unit_bytes", f"unit {chunk.unit!r}: the open test passes "
                    f"{self.bounds.limits.unit_bytes} bytes with no {{\"end\": true}} "
                    f"([stream] unit_bytes); its {held} samples are dropped")
            if held + chunk.samples > self.max_test_samples:
                self._drop_test(chunk.unit)
                raise DataError(f"unit {chunk.unit!r}: the test passes {self.max_test_samples} "
                                "samples with no {\"end\": true} ([stream] max_test_samples); "
                                f"its {held} samples are dropped")
            if parts and chunk.columns["t"][0] <= parts[-1]["t"][-1]:
                self.counters.dropped += 1
                self.log(f"{chunk.unit}: chunk dropped, it does not follow the last one "
                         f"(t = {chunk.columns['t'][0]:g} s after {parts[-1]['t'][-1]:g} s)")
                self._finish(chunk.ref)
            else:
                self.bounds.take(chunk.unit, size)
                parts.append(chunk.columns)
                if chunk.ref is not None:
                    refs.append(chunk.ref)
        elif chunk.ref is not None:
            refs.append(chunk.ref)
        if not chunk.end:
            return []
        if not parts:
            self._drop_test(chunk.unit)
            raise DataError(f"unit {chunk.unit!r}: 'end' with no samples before it")
        frame = pd.DataFrame({c: np.concatenate([p[c] for p in parts if c in p])
                              for c in parts[0]})
        frame.attrs["source"] = f"{chunk.unit} stream"
        _mark_si(frame, self.machine_of(chunk.unit)[1])
        try:
            event = self._check(chunk.unit, name, frame)
        except StoreError:
            raise  # not stored: the journal keeps the test for the next start
        except DuplicateTestError as exc:  # a replay of a test stored before a stop
            event = self._event(chunk.unit, self._status.get(chunk.unit, "go"),
                                f"test #{exc.test_id} already stored; not stored again",
                                "checked")
        except Exception:
            self._drop_test(chunk.unit)  # refused: said by the caller, done with
            raise
        self._drop_test(chunk.unit)
        return [event]

    def _drop_test(self, unit: str) -> None:
        """Forget a unit's open test; its chunks are done with."""
        parts = self._tests.pop(unit, [])
        self.bounds.give(unit, sum(nbytes(p) for p in parts))
        self._finish(*self._test_refs.pop(unit, []))

    def _check(self, unit: str, name: str, frame: pd.DataFrame) -> WatchEvent:
        from condmon.workflows.checks import check_test
        from condmon.workflows.monitoring import add_baseline_tests, baseline_members
        from condmon.workflows.records import EstimateOptions

        opts = EstimateOptions(model=name)
        if not self.store.unit_model(unit) or len(baseline_members(self.store, unit)[0]) < 3:
            added = add_baseline_tests(self.store, unit, [frame], options=opts)
            self.counters.checks += 1
            n = len(baseline_members(self.store, unit)[0])
            accepted = any(t.accepted for t in added.tests)
            state = ("baseline ready: the next tests are checked against it"
                     if added.baseline is not None else
                     f"{n} of 3 healthy tests for its baseline so far")
            what = "test kept for the baseline" if accepted else "test rejected"
            return self._event(unit, "baseline", f"{what}: {state}", "baseline")
        res = check_test(self.store, unit, frame, options=opts)
        self.counters.checks += 1
        summary = res.diagnosis.summary if res.diagnosis is not None else str(
            res.estimate.reason)
        return self._event(unit, res.status, f"test #{res.test_id}: {summary}", "checked")

    def _event(self, unit: str, status: str, reason: str, kind: str,
               isolated: tuple[str, ...] = (), stream_time: float | None = None) -> WatchEvent:
        self._status[unit] = status
        self.counters.events += 1
        event = WatchEvent(unit, status, _now(), reason, isolated, kind,
                           None if stream_time is None or not math.isfinite(stream_time)
                           else stream_time)
        self.publish(event)
        return event


def _mark_si(frame: pd.DataFrame, machine: Machine) -> None:
    """A streamed test in the model's own columns (``t`` and every sensor under
    the model's names, none of the rig's file names) is in SI units, as the
    stream contract says: the declaration's ``[record]`` table (the rig's file
    names and raw units) is not applied to it. A test in the rig's columns is
    read as its files are."""
    names = {"t", *machine.plant.sensor_names}
    rig = {f for k, f in machine.record.columns.items() if f != k}
    if names <= set(frame.columns) and not rig & set(frame.columns):
        frame.attrs["record_settings"] = "model columns in SI, as streamed"
