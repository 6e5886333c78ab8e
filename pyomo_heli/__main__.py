"""``python -m pyomo_heli ...`` is the ``pyomo-heli`` command."""
import sys

from .cli import main

sys.exit(main())
