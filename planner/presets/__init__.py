"""Preset style files (TOML) shipped with the planner; read them with ``planner.load_style(name)``."""
