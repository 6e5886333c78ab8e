"""Performance benchmark: build, set-up, solve, warm vs cold front, single shooting, scaling (docs/performance.md).

The study is ``pyomo_heli.studies.benchmark``;
``python studies/benchmark.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.benchmark import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
