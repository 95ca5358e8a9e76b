"""The GUI's widgets: the main window (built in :mod:`~ui.views.window_layout`, its correcting
actions in :mod:`~ui.views.window_actions`), the video, posture and timeline views, the frame
and marker tables, the correction panel and sliders, the key table and the colours."""
