"""Fighters that play the game API (igraph_fight.game): the Interaction Graph fighter and baselines.

IGAgent (Interaction Graph), RandomAgent, GameTreeAgent (min-max on the exact simulator),
StaticAgent (trained against a static target), HumanProxyAgent (scripted reactive proxy),
RLAgent (masked PPO policy; torch is imported when one is built).
"""
from .base import Agent, RandomAgent
from .gametree import GameTreeAgent, GameTreeSearch
from .human import HumanConfig, HumanProxyAgent
from .ig import IGAgent
from .rl import RLAgent
from .static import StaticAgent, train_static

__all__ = ["Agent", "RandomAgent", "IGAgent", "GameTreeAgent", "GameTreeSearch", "HumanConfig", "HumanProxyAgent",
           "RLAgent", "StaticAgent", "train_static"]
