"""The PySide6 + pyqtgraph desktop GUI (``videotrack gui``); nothing else imports it."""

from PySide6.QtCore import QCoreApplication, Qt

if QCoreApplication.instance() is None:
    # pyqtgraph's 3D items compile their shader programs once per process; without one shared
    # OpenGL context a second window's 3D view draws nothing but GL errors ("glUseProgram:
    # invalid value"), seen under a real X server. Qt takes this only before the application.
    QCoreApplication.setAttribute(Qt.ApplicationAttribute.AA_ShareOpenGLContexts)
