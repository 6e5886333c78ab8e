"""How often the loop's score test fires when no effect is missing (docs/close_loop.md).

The study is ``pyomo_heli.studies.score_test_level``;
``python studies/score_test_level.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.score_test_level import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
