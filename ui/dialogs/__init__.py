"""The GUI's dialogs: project settings (with its generated forms), the chain editor, the
histograms and the shortcut sheet."""
