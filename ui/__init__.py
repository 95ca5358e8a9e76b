"""The PySide6 + pyqtgraph desktop GUI (``videotrack gui``); nothing else imports it."""
