import sys

from igraph_fight.cli import main

sys.exit(main())
