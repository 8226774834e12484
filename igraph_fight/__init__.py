"""igraph_fight."""
