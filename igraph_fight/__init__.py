"""igraph_fight: the coupled two-fighter state, the kinematic interaction simulator, the
Interaction Graph build, the runtime NPC controller and the game API.

    from igraph_fight import NPCController, Observation, FightGame
"""
from .controller import Decision, NPCController, Observation, observe
from .game import FightGame, FightState, GameConfig
from .graph import GraphFormatError, InteractionGraph, load_graph
from .sim import SimParams, SimTables
from .state import PaperState, WorldState

__all__ = ["Decision", "NPCController", "Observation", "observe", "FightGame", "FightState", "GameConfig",
           "GraphFormatError", "InteractionGraph", "load_graph", "SimParams", "SimTables", "PaperState", "WorldState"]
