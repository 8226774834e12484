"""Play against the Interaction Graph: a browser game against the NPC and a network NPC service
for game engines, both served by `igraph-fight play` (paper section 7.1, the game interface).

- ``commands``: the player's high-level commands, the key map, command -> action (with fallbacks)
- ``session``: a bout stepped in real time (player = fighter A, NPC = fighter B), streamed frames
- ``bouts``: saving bouts (the `fight` log format) and replaying them
- ``protocol``, ``service``, ``policies``: the versioned JSON protocol, the NPC service, policy tables
- ``server``: the aiohttp server (page, /health, POST /decide, WebSockets /ws and /game)
- ``demo_graph``: the cached demo graph used without --graph; ``drawing``: what the page draws
- ``web/``: the page (index.html, static/), three.js from npm (web/node_modules, not committed)
"""
