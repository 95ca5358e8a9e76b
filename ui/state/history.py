"""Undoable edits, the undo and redo stacks and what is unsaved (a part of
:class:`ui.state.Session`). Every change of results, pins, chain or detection edits is an
:class:`Edit`."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from kinematics.errors import LocatedError
from kinematics.model import Body
from ui.state import backend


@dataclass
class Edit:
    """One undoable change: results of some frames, their pinned axes, and/or the chain.

    Each entry maps to ``(before, after)``; None stands for "absent".
    """

    label: str
    results: dict[int, tuple] = field(default_factory=dict)
    pins: dict[int, tuple] = field(default_factory=dict)
    body: tuple[Body, Body] | None = None
    stale: tuple[frozenset, frozenset] | None = None  # Session.stale before and after
    detection_edits: tuple[dict, dict] | None = None  # Session.detection_edits

    def record_result(self, frame: int, before, after) -> None:
        old = self.results.get(frame, (before, None))[0]
        self.results[frame] = (old, after)

    def record_pins(self, frame: int, before, after) -> None:
        old = self.pins.get(frame, (before, None))[0]
        self.pins[frame] = (old, after)

    def __bool__(self) -> bool:
        return bool(self.results or self.pins or self.body or self.detection_edits)



class HistoryMixin:
    """Edits applied, undone and redone; unsaved parts."""

    # -- edits, undo, dirty -------------------------------------------------------------
    @property
    def dirty(self) -> bool:
        return bool(self._dirty)

    @property
    def unsaved(self) -> list[str]:
        """What has unsaved changes: ``config``, ``chain``, ``detection edits`` and/or
        ``results``."""
        return sorted(self._dirty)

    def _mark(self, *parts: str) -> None:
        was = self.dirty
        self._dirty.update(parts)
        if not was:
            self.dirtyChanged.emit(True)

    def _apply(self, edit: Edit, which: int) -> None:
        """Set the state of ``edit``: ``which`` 0 for before (undo), 1 for after (redo)."""
        if edit.stale is not None:
            self.stale = set(edit.stale[which])
        for frame, pair in edit.results.items():
            if pair[which] is None:
                self.results.pop(frame, None)
            else:
                self.results[frame] = pair[which]
        for frame, pair in edit.pins.items():
            if pair[which]:
                self.pins[frame] = dict(pair[which])
            else:
                self.pins.pop(frame, None)
        if edit.results:
            self._mark("results")
            self.resultsChanged.emit(sorted(edit.results))
        if edit.body is not None:
            self.body = edit.body[which]
            self._mark("chain")
            self.bodyChanged.emit()
        if edit.detection_edits is not None:
            self.detection_edits = edit.detection_edits[which]
            self._mark("detection edits")
            self.frameChanged.emit(self.frame)  # redraw the detections

    def _freshen(self, edit: Edit, frames) -> None:
        """These frames' results are now of the current chain (recorded in ``edit``)."""
        before = frozenset(self.stale) if edit.stale is None else edit.stale[0]
        self.stale.difference_update(frames)
        edit.stale = (before, frozenset(self.stale))

    def _push(self, edit: Edit) -> None:
        if edit:
            self._undo.append(edit)
            self._redo.clear()
            self.undoChanged.emit()

    @property
    def can_undo(self) -> bool:
        return bool(self._undo) and not self.busy

    @property
    def can_redo(self) -> bool:
        return bool(self._redo) and not self.busy

    @property
    def undo_label(self) -> str:
        return self._undo[-1].label if self._undo else ""

    @property
    def redo_label(self) -> str:
        return self._redo[-1].label if self._redo else ""

    def undo(self) -> None:
        if not self.can_undo:
            return
        edit = self._undo.pop()
        self._apply(edit, 0)
        self._redo.append(edit)
        self.status.emit(f"undid: {edit.label}")
        self.undoChanged.emit()

    def redo(self) -> None:
        if not self.can_redo:
            return
        edit = self._redo.pop()
        self._apply(edit, 1)
        self._undo.append(edit)
        self.status.emit(f"redid: {edit.label}")
        self.undoChanged.emit()

    def commit_body(self, body: Body, label: str = "edit chain",
                    geometry: bool = True) -> bool:
        """Make ``body`` the session's chain (undoable); it is validated first.

        ``geometry`` False for a change that leaves the projection alone (histograms);
        otherwise every result becomes :attr:`stale` until its frame is fitted again.
        """
        from kinematics.model import validate_body

        try:
            validate_body(body)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        self.preview_body = None
        before = frozenset(self.stale)
        edit = Edit(label, body=(self.body, body),
                    stale=(before, before | set(self.results) if geometry else before))
        self._apply(edit, 1)
        self._push(edit)
        if geometry and self.stale:
            self.status.emit(f"chain changed: the errors of {len(self.stale)} frames are of "
                             "the previous chain until they are fitted again")
        return True

    def set_results(self, results: Iterable, label: str) -> None:
        """Store results (e.g. of a fit) as one undoable edit; their pins are released."""
        edit = Edit(label)
        for r in results:
            edit.record_result(r.frame, self.results.get(r.frame), r)
            if r.frame in self.pins and r.status != backend.CORRECTED:
                edit.record_pins(r.frame, self.pins[r.frame], None)
        self._freshen(edit, list(edit.results))
        self._apply(edit, 1)
        self._push(edit)

