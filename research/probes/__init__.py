"""Probe scripts cited by the research notes (``python -m research.probes.NAME`` from the repository root)."""
