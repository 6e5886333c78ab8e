"""``python -m pyomo_heli.cli ...`` is the ``pyomo-heli`` command."""
import sys

from . import main

sys.exit(main())
