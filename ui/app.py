"""Start the GUI: ``videotrack gui [PROJECT.toml]`` calls :func:`run`."""

from __future__ import annotations

import sys


def run(project=None, trial: str | None = None, argv: list[str] | None = None) -> int:
    """Open the main window (on ``project``, or on a ``trial`` of the project folder
    ``project``, if given) and run the event loop.

    Returns the application's exit code.
    """
    from PySide6.QtWidgets import QApplication

    from ui.views.main_window import MainWindow

    app = QApplication.instance() or QApplication(argv if argv is not None else sys.argv[:1])
    app.setApplicationName("VideoTrack")
    app.setOrganizationName("VideoTrack")
    window = MainWindow()
    window.show()
    if project is not None:
        window.open_project(project, trial)
    return app.exec()
