"""Ready-made chain files, installed as ``videotrack.chains`` (see docs/chains.md)."""
