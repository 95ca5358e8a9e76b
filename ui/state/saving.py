"""Writing what changed: project config, chain file, detection edits and results (a part
of :class:`ui.state.Session`)."""

from __future__ import annotations

from dataclasses import replace

from kinematics.errors import LocatedError
from kinematics.model import Body
from ui.state import backend
from videotrack.detect import edits as detection_edits


class SavingMixin:
    """Saving the project's changed parts and the chain."""

    # -- chain file ---------------------------------------------------------------------
    def save_chain_as(self, path, body: Body | None = None) -> bool:
        """Write the chain (or ``body``) as chain XML (histograms included)."""
        from kinematics.model.chain_xml import save_body

        try:
            save_body(path, body or self.body)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        self.status.emit(f"wrote chain to {path}")
        return True


    # -- saving -------------------------------------------------------------------------
    def save(self) -> bool:
        """Write what changed: the project config, the chain file, the results file."""
        from kinematics.fileio import atomic_write_text
        from kinematics.model.chain_xml import save_body

        try:
            if "config" in self._dirty:
                from videotrack.project.config import updated_toml_text

                # edit the file in place: the user's comments and layout survive
                text = self.config.path.read_text(encoding="utf-8")
                atomic_write_text(self.config.path, updated_toml_text(text, self.raw_config))
            if "chain" in self._dirty and self.model is not None:
                save_body(self.model.chain_path, self.body)
            if "detection edits" in self._dirty and self.results_path is not None:
                path = detection_edits.edits_path(self.results_path)
                if self.detection_edits or path.exists():
                    detection_edits.save_edits(path, self.detection_edits, self.view_names)
            if "results" in self._dirty and self.model is not None:
                model = replace(self._fit_model(), body=self.body, params=self.params)
                backend.save_project_results(self.results_path, model, self.body,
                                             self.results, self._records(),
                                             self.detections_path, self.measured_noise)
        except LocatedError as err:
            self.error.emit(str(err))
            return False
        except OSError as err:
            self.error.emit(f"{err.filename}: {err.strerror}")
            return False
        saved = ", ".join(self.unsaved) or "nothing to save"
        self._dirty.clear()
        self.dirtyChanged.emit(False)
        self.status.emit(f"saved {saved}")
        return True
