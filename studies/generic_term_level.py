"""How far generic terms' NLP estimates move when nothing is missing (docs/generic_term_level.md).

The study is ``pyomo_heli.studies.generic_term_level``;
``python studies/generic_term_level.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.generic_term_level import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
