"""Fighters that play the game API (igraph_fight.game): the Interaction Graph fighter and baselines."""
from .base import Agent, RandomAgent
from .ig import IGAgent

__all__ = ["Agent", "RandomAgent", "IGAgent"]
