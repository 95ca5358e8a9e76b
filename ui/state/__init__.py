"""The GUI's state: one :class:`Session` (a QObject with the signals widgets redraw on),
assembled from a module per concern, and the library doors it goes through
(:mod:`ui.state.backend`, no Qt; :mod:`ui.state.workers`, the threads of long work)."""

from ui.state.session import Session

__all__ = ["Session"]
