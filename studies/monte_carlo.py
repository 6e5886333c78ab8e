"""Monte Carlo over noise realisations: bias and spread of the estimates (docs/uncertainty.md).

The study is ``pyomo_heli.studies.monte_carlo``;
``python studies/monte_carlo.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.monte_carlo import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
