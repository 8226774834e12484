"""The controller interface shared by the PD baseline and learned policies, and the registry of
the controllers the command line builds by name.

A controller is asked once per control step for PD position targets (absolute, in the actuators'
coordinates, all fighters concatenated). It may set the PD gains it was tuned with when reset.

    class Controller(Protocol):
        name: str
        def reset(self, env: TrackingEnv) -> None: ...
        def act(self, env: TrackingEnv, obs: np.ndarray) -> np.ndarray: ...

``CONTROLLERS`` is an explicit table name -> factory(ckpt); ``make_controller(name, ckpt)`` builds
one (``igraph-fight tracker eval --controller NAME [--ckpt CKPT]``). Any other object with
``reset`` and ``act`` can be handed to the evaluation directly (tracker.track.evaluation).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from tracker.track.env import TrackingEnv


@runtime_checkable
class Controller(Protocol):
    name: str

    def reset(self, env: "TrackingEnv") -> None:
        """Called after env.reset(); may set gains (env.set_gains) and clear internal state."""

    def act(self, env: "TrackingEnv", obs: np.ndarray) -> np.ndarray:
        """(env.n_act,) absolute PD position targets for the next control step."""


def pd_controller(ckpt: str | None = None) -> Controller:
    """The PD baseline (default gains, or a JSON file of gains)."""
    from tracker.track.pd import PDController
    return PDController.from_ckpt(ckpt)


def balance_controller(ckpt: str | None = None) -> Controller:
    """PD with the virtual-force balance layer (tracker.track.vforce): the gains file's "balance"
    gains, else the layer's defaults."""
    from tracker.track.pd import PDController
    pd = PDController.from_ckpt(ckpt)
    if pd.balance is None:            # no gains file, or one without "balance": the layer's default gains
        from dataclasses import replace

        from tracker.track.vforce import BalanceGains
        pd = replace(pd, balance=BalanceGains().as_tuple(), name="balance")
    return pd


def learned_controller(ckpt: str | None = None) -> Controller:
    """The learned policy of a checkpoint (default: the shipped one, tracker/checkpoints/boxing_cmu13.pt)."""
    from tracker.track.policy_net import load_policy
    return load_policy(ckpt)


#: name -> factory(ckpt: str | None) -> Controller: every controller the command line knows.
CONTROLLERS: dict[str, Callable[[str | None], Controller]] = {
    "pd": pd_controller,
    "balance": balance_controller,
    "learned": learned_controller,
}


def make_controller(name: str, ckpt: str | None = None) -> Controller:
    """Build a controller by name ("pd", "balance", "learned")."""
    factory = CONTROLLERS.get(name)
    if factory is None:
        raise ValueError(f"unknown controller {name!r}; available: {', '.join(CONTROLLERS)}")
    return factory(ckpt)
