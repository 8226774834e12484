"""Experiments behind the tracker's design, not part of the installed product (run from the
repository root: ``python -m research.NAME``). Nothing in the packages imports this folder."""
