"""Fighters that play the game API (igraph_fight.game): the Interaction Graph fighter and baselines.

IGAgent (Interaction Graph), RandomAgent, GameTreeAgent (min-max on the exact simulator),
StaticAgent (trained against a static target), HumanProxyAgent (scripted reactive proxy),
RLAgent (masked PPO policy; torch is imported when one is built).
"""
from igraph_fight.agents.base import Agent, RandomAgent
from igraph_fight.agents.gametree import GameTreeAgent, GameTreeSearch
from igraph_fight.agents.human import HumanConfig, HumanProxyAgent
from igraph_fight.agents.ig import IGAgent
from igraph_fight.agents.rl import RLAgent
from igraph_fight.agents.static import StaticAgent, train_static

__all__ = ["Agent", "RandomAgent", "IGAgent", "GameTreeAgent", "GameTreeSearch", "HumanConfig", "HumanProxyAgent",
           "RLAgent", "StaticAgent", "train_static"]
