"""List (default) or run the commands that regenerate docs/results (docs/results.md, "Regenerating").

The study is ``pyomo_heli.studies.regenerate``;
``python studies/regenerate_docs.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.regenerate import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
