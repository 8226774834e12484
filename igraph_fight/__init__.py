"""igraph_fight: the coupled two-fighter state, the kinematic interaction simulator, the
Interaction Graph build, the runtime NPC controller and the game API.

    from igraph_fight import NPCController, Observation, FightGame
"""
from igraph_fight.controller import Decision, NPCController, Observation, observe
from igraph_fight.game import FightGame, FightState, GameConfig
from igraph_fight.graph import GraphFormatError, InteractionGraph, load_graph
from igraph_fight.sim import SimParams, SimTables
from igraph_fight.state import PaperState, WorldState

__all__ = ["Decision", "NPCController", "Observation", "observe", "FightGame", "FightState", "GameConfig",
           "GraphFormatError", "InteractionGraph", "load_graph", "SimParams", "SimTables", "PaperState", "WorldState"]
