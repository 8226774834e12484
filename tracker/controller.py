"""The controller interface shared by the PD baseline and learned policies.

A controller is asked once per control step for PD position targets (absolute, in the actuators'
coordinates, all fighters concatenated). It may set the PD gains it was tuned with when reset.

    class Controller(Protocol):
        name: str
        def reset(self, env: TrackingEnv) -> None: ...
        def act(self, env: TrackingEnv, obs: np.ndarray) -> np.ndarray: ...

A learned policy of the next issue implements the same two methods (e.g. ``act`` returns
``env.reference_targets() + policy(obs)`` for a residual policy) and is registered in
``CONTROLLERS`` / built by ``make_controller`` so ``tracker eval --controller learned --ckpt ...``
finds it.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from .env import TrackingEnv


@runtime_checkable
class Controller(Protocol):
    name: str

    def reset(self, env: "TrackingEnv") -> None:
        """Called after env.reset(); may set gains (env.set_gains) and clear internal state."""

    def act(self, env: "TrackingEnv", obs: np.ndarray) -> np.ndarray:
        """(env.n_act,) absolute PD position targets for the next control step."""


#: name -> factory(ckpt: str | None) -> Controller. The learned policy registers itself here.
CONTROLLERS: dict[str, Callable[[str | None], Controller]] = {}


def register_controller(name: str, factory: Callable[[str | None], Controller]) -> None:
    CONTROLLERS[name] = factory


def make_controller(name: str, ckpt: str | None = None) -> Controller:
    """Build a controller by name ("pd", "learned", ...)."""
    if name == "pd":
        from .pd import PDController
        return PDController.from_ckpt(ckpt)
    if name == "balance":
        from .pd import PDController
        pd = PDController.from_ckpt(ckpt)
        if pd.balance is None:            # no gains file, or one without "balance": the layer's default gains
            from dataclasses import replace
            from .vforce import BalanceGains
            pd = replace(pd, balance=BalanceGains().as_tuple(), name="balance")
        return pd
    if name not in CONTROLLERS:
        mod = {"learned": "tracker.policy", "search": "tracker.search_controller",
               "search-fast": "tracker.search_controller"}.get(name)
        if mod:
            try:  # the module registers the controller when imported
                import importlib
                importlib.import_module(mod)
            except ModuleNotFoundError:
                pass
        if name not in CONTROLLERS:
            raise ValueError(f"unknown controller {name!r}; available: pd, balance{''.join(', ' + k for k in CONTROLLERS)}")
    return CONTROLLERS[name](ckpt)
