"""The PySide6 + pyqtgraph desktop GUI (``videotrack gui``); nothing else imports it."""

from ui._refcount_guard import protect_singletons

protect_singletons()
