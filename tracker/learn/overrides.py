"""``--set KEY=VALUE`` overrides of a config dataclass (tracker.learn.train_tracker, tracker.bouts.rl_agent)."""
from __future__ import annotations

from dataclasses import asdict


def parse_config_overrides(items: list[str] | None, cls: type) -> dict:
    """``["gamma=0.97", "hidden=256,256"]`` -> overrides typed like ``cls()``'s defaults (bools take
    1/true/yes; tuples are comma lists of the default's element type, floats for an empty default).
    Raises ValueError naming the item, the unknown field or the bad value."""
    defaults = asdict(cls())
    name = cls.__name__
    out = {}
    for it in items or []:
        k, eq, v = it.partition("=")
        if not eq:
            raise ValueError(f"--set {it!r}: expected KEY=VALUE")
        if k not in defaults:
            raise ValueError(f"--set: unknown {name} field {k!r} (fields: {', '.join(defaults)})")
        d = defaults[k]
        try:
            if isinstance(d, bool):
                out[k] = v.lower() in ("1", "true", "yes")
            elif isinstance(d, tuple):
                elem = type(d[0]) if d else float
                out[k] = tuple(elem(x) for x in v.split(","))
            else:
                out[k] = type(d)(v)
        except ValueError:
            raise ValueError(f"--set {k}={v!r}: not a valid {type(d).__name__} for {name}") from None
    return out
