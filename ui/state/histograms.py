"""Learning, exporting and importing the chain's histograms (a part of
:class:`ui.state.Session`)."""

from __future__ import annotations

from pathlib import Path

from kinematics.errors import LocatedError
from ui import adapters
from ui.state.workers import error_text


class HistogramsMixin:
    """Histograms of the chain: Eq. 4 learning and archive files."""

    # -- histograms ---------------------------------------------------------------------
    def learn_histograms(self, within_threshold: bool = True) -> int:
        """Eq. 4 learning from the analysed frames: those within the current threshold
        (corrected, or E ≤ :attr:`threshold` now, see :func:`ui.adapters.trusted`), or every
        fitted frame. Returns the number of frames learned from (0: nothing changed).
        """
        from kinematics.model.histogram_xml import apply_archive, archive_from_body, update_archive

        angles = (adapters.learning_angles(self.results, threshold=self.threshold)
                  if within_threshold else adapters.learning_angles(self.results, None))
        if self.body is None or len(angles) == 0:
            self.status.emit("no analysed frames to learn from")
            return 0
        archive = update_archive(archive_from_body(self.body), self.body, angles)
        self.commit_body(apply_archive(self.body, archive),
                         f"learn histograms from {len(angles)} frames", geometry=False)
        self.status.emit(f"histograms learned from {len(angles)} frames (Eq. 4)")
        return len(angles)

    def export_histograms(self, path) -> bool:
        """Write every axis' histogram to a histogram archive XML."""
        from kinematics.model.histogram_xml import archive_from_body, save_archive

        try:
            save_archive(path, archive_from_body(self.body))
        except (LocatedError, OSError) as err:
            self.error.emit(error_text(err) if isinstance(err, LocatedError) else
                            f"{path}: {err.strerror}")
            return False
        self.status.emit(f"wrote histograms to {path}")
        return True

    def import_histograms(self, path) -> bool:
        """Apply a histogram archive to the chain (undoable)."""
        from kinematics.model.histogram_xml import apply_archive, load_archive

        try:
            body = apply_archive(self.body, load_archive(path))
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        return self.commit_body(body, f"load histograms from {Path(path).name}",
                                geometry=False)

