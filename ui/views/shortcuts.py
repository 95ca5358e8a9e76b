"""The one table of the window's commands and their keys.

:class:`ui.views.main_window.MainWindow` makes one QAction per row (text, keys, tip, what it does)
and the shortcut sheet (``?``) and the key table of ``docs/gui.md`` are generated from the
same rows, so neither can disagree with the keys that work. Rows without ``run`` are keys a
widget handles itself (listed so the sheet is complete); rows without keys are menu commands.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from PySide6.QtGui import QKeySequence


@dataclass(frozen=True)
class Command:
    """One command: ``name`` is the window's action attribute without ``act_``."""

    name: str
    text: str  # menu text (with & for the mnemonic)
    keys: tuple[str, ...]  # QKeySequence portable texts, the first shown in menus
    group: str  # section of the sheet
    tip: str = ""
    run: Callable | None = None  # run(window); None: handled by a widget, not an action

    @property
    def label(self) -> str:
        """Menu text without the mnemonic."""
        return self.text.replace("&", "")

    def key_text(self) -> str:
        """The keys as the sheet and docs show them: ``Ctrl+Right / Ctrl+Left``."""
        return " / ".join(self.keys)

    def sequences(self) -> list[QKeySequence]:
        return [QKeySequence(k) for k in self.keys]


def _s(window):
    return window.session


COMMANDS: tuple[Command, ...] = (
    # -- files
    Command("open", "&Open project…", ("Ctrl+O",), "File",
            "Open a project file (TOML)", lambda w: w.choose_project()),
    Command("save", "&Save", ("Ctrl+S",), "File",
            "Save the project config, chain, results and detection edits that changed",
            lambda w: _s(w).save()),
    Command("chain_file", "Choose &chain file…", (), "File",
            "Use another chain XML for this project", lambda w: w.choose_chain_file()),
    Command("quit", "&Quit", ("Ctrl+Q",), "File", "", lambda w: w.close()),
    # -- editing
    Command("undo", "&Undo", ("Ctrl+Z",), "Edit", "", lambda w: _s(w).undo()),
    Command("redo", "&Redo", ("Ctrl+Shift+Z",), "Edit", "", lambda w: _s(w).redo()),
    Command("chain_editor", "Chain &editor…", ("Ctrl+E",), "Edit",
            "Edit lengths, orientations, markers and ranges", lambda w: w.open_chain_editor()),
    Command("settings", "&Project settings…", ("Ctrl+P",), "Edit",
            "Views, filters with live preview, chain and fitting",
            lambda w: w.open_project_dialog()),
    # -- analysis
    Command("detect", "&Detect markers", ("Ctrl+D",), "Analysis",
            "Run the filter chain on every frame and save the detections",
            lambda w: _s(w).detect()),
    Command("fit_all", "Fit &all frames", ("F5",), "Analysis",
            "Fit every frame that was not corrected or accepted by hand",
            lambda w: _s(w).fit(label="fit all")),
    Command("fit_current", "Fit &current frame", ("F6",), "Analysis", "",
            lambda w: _s(w).fit([_s(w).frame], "fit frame")),
    Command("fit_range", "Fit &range…", (), "Analysis", "Fit frames A to B",
            lambda w: w.fit_range()),
    Command("fit_selected", "Fit &selected frames", ("F7",), "Analysis",
            "Fit the frames selected in the table", lambda w: w.fit_selected()),
    Command("fit_bad", "Re-fit &bad frames", ("F8",), "Analysis",
            "Fit again every frame above the error threshold", lambda w: _s(w).fit_bad()),
    Command("cancel", "Cancel", ("Esc",), "Analysis", "Stop the running task",
            lambda w: _s(w).cancel()),
    Command("histograms", "&Histograms…", ("Ctrl+H",), "Analysis",
            "Each axis' histogram with the current value", lambda w: w.open_histograms()),
    # -- moving through the video
    Command("play", "Play / pause", ("Space",), "Frames", "",
            lambda w: w.toggle_play()),
    Command("next", "Next frame", ("Right",), "Frames", "", lambda w: _s(w).step(1)),
    Command("prev", "Previous frame", ("Left",), "Frames", "", lambda w: _s(w).step(-1)),
    Command("next10", "Forward 10 frames", ("Shift+Right",), "Frames", "",
            lambda w: _s(w).step(10)),
    Command("prev10", "Back 10 frames", ("Shift+Left",), "Frames", "",
            lambda w: _s(w).step(-10)),
    Command("first", "First frame", ("Home",), "Frames", "", lambda w: _s(w).set_frame(0)),
    Command("last", "Last frame", ("End",), "Frames", "",
            lambda w: _s(w).set_frame(_s(w).n_frames - 1)),
    Command("next_bad", "Next frame needing attention", ("Ctrl+Right",), "Frames",
            "The next frame above the threshold, failed, re-analysed or ambiguous (not "
            "corrected or accepted)", lambda w: w.next_attention(1)),
    Command("prev_bad", "Previous frame needing attention", ("Ctrl+Left",), "Frames",
            "The previous frame above the threshold, failed, re-analysed or ambiguous",
            lambda w: w.next_attention(-1)),
    Command("table_rows", "Previous / next row of the table", ("Up", "Down"), "Frames",
            "In the error table (it has the focus): its frame is shown"),
    # -- correcting
    Command("accept_next", "Accept and go to &next", ("Ctrl+Return",), "Correct",
            "Mark this frame's posture right (status corrected) and go to the next frame "
            "needing attention", lambda w: w.accept_and_next()),
    Command("accept_selected", "A&ccept selected frames", ("Ctrl+Shift+Return",), "Correct",
            "Mark the fitted frames selected in the table right (status corrected)",
            lambda w: w.accept_selected()),
    Command("swap", "&Alternative posture", ("A",), "Correct",
            "Replace this frame's posture by the next candidate the fit kept (an ambiguous "
            "frame's mirror posture, drawn dashed), and the neighbours on the same wrong "
            "branch; again to cycle", lambda w: _s(w).swap_candidate()),
    Command("prev_axis", "Select previous axis", ("[",), "Correct",
            "The axis the nudge keys move (bold frame in Manual correction)",
            lambda w: w.correction.select_axis(-1)),
    Command("next_axis", "Select next axis", ("]",), "Correct", "",
            lambda w: w.correction.select_axis(1)),
    Command("nudge_down", "Nudge axis −0.1°", (",",), "Correct",
            "Turn the selected axis; the frame is re-fitted once the keys rest",
            lambda w: w.correction.nudge(-0.1)),
    Command("nudge_up", "Nudge axis +0.1°", (".",), "Correct", "",
            lambda w: w.correction.nudge(0.1)),
    Command("nudge_down_big", "Nudge axis −1°", ("Ctrl+,",), "Correct", "",
            lambda w: w.correction.nudge(-1.0)),
    Command("nudge_up_big", "Nudge axis +1°", ("Ctrl+.",), "Correct", "",
            lambda w: w.correction.nudge(1.0)),
    Command("marker_left", "Nudge marker left 0.5 px", ("Alt+Left",), "Correct",
            "Move the selected model marker (click it in a video view); the frame is "
            "re-fitted around it once the keys rest, as after a drag",
            lambda w: w.nudge_marker(-1, 0)),
    Command("marker_right", "Nudge marker right 0.5 px", ("Alt+Right",), "Correct", "",
            lambda w: w.nudge_marker(1, 0)),
    Command("marker_up", "Nudge marker up 0.5 px", ("Alt+Up",), "Correct", "",
            lambda w: w.nudge_marker(0, -1)),  # image rows grow downwards
    Command("marker_down", "Nudge marker down 0.5 px", ("Alt+Down",), "Correct", "",
            lambda w: w.nudge_marker(0, 1)),
    Command("hide_marker", "&Hide / show marker in this view", ("H",), "Correct",
            "Mark the selected model marker hidden in its view (occluded, or merged with "
            "another blob) or seen again: the fit leaves it out there. Over the table "
            "selection when the frame shown is in it", lambda w: w.toggle_hidden()),
    Command("refit_forward", "Re-fit &forward from here", ("F9",), "Correct",
            "Seed the following frames with this posture, one after the other, until the "
            "error exceeds the threshold or a corrected frame", lambda w: w.refit_from(1)),
    Command("refit_backward", "Re-fit &backward from here", ("Shift+F9",), "Correct",
            "The same towards the start of the video", lambda w: w.refit_from(-1)),
    Command("interpolate", "&Interpolate pinned axes", ("I",), "Correct",
            "Over the table selection (or from the previous corrected frame to this one): "
            "pinned axes linear between the two corrected ends, the rest re-fitted",
            lambda w: w.interpolate()),
    Command("help", "&Keyboard shortcuts", ("?", "F1"), "Help", "This sheet",
            lambda w: w.show_shortcuts()),
)

BY_NAME = {c.name: c for c in COMMANDS}


def keyed() -> list[Command]:
    """The commands that have keys, in table order."""
    return [c for c in COMMANDS if c.keys]


def markdown_table() -> str:
    """The key table of ``docs/gui.md`` (a test checks the docs hold it verbatim)."""
    rows = ["| key | action |", "| --- | --- |"]
    rows += [f"| {' / '.join(f'`{k}`' for k in c.keys)} | {c.label} |" for c in keyed()]
    return "\n".join(rows)


if __name__ == "__main__":  # python -m ui.views.shortcuts: the table for docs/gui.md
    print(markdown_table())
