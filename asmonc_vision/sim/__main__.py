"""``python -m asmonc_vision.sim``: see ``asmonc_vision.sim.cli``."""
import sys

from asmonc_vision.sim.cli import main

sys.exit(main())
