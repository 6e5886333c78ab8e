import os
import sys

# One BLAS thread per test process, set before numpy loads. `pytest -n 2` runs two workers on CI's two cores; each
# worker's OpenBLAS would start a thread per core and spin-wait on the other's core (measured on one
# identification fixture: 61 s of system time in 93 s without this, 11 s with it).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# Bytecode caches: the README installs with `pip install --no-compile` (byte-compiling every installed file took half
# of the install), so a module is compiled when it is first imported. Where the environment says not to write the
# caches (PYTHONDONTWRITEBYTECODE), every process would compile every module it imports again: 6.6 s a process for
# the package and its dependencies on the project's machine, and the tests start about 40 commands. The test run and
# the commands it starts write them.
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False

import pytest  # noqa: E402


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run paper-scale slow studies")


#: the test files that take longest, longest first (seconds of one worker in the default run, summed from
#: `pytest -n 2 --dist loadfile --junitxml`): discovery 215, identification 140, trim_loop 115, close_loop 100,
#: close_loop_wake, interrupts and flighttest 85 each, ... . `--dist loadfile` (with `--no-loadscope-reorder`,
#: pyproject.toml) hands the files to the two workers in collection order; a long file handed out last
#: (test_close_loop_wake was) leaves the other worker idle to the end. Longest first, the two end close together.
LONGEST_FIRST = ("test_discovery.py", "test_identification.py", "test_trim_loop.py", "test_close_loop_wake.py",
                 "test_close_loop.py", "test_flighttest.py", "test_interrupts.py", "test_input_path.py",
                 "test_uncertainty.py", "test_check_effect.py", "test_innovations.py", "test_held_out_effects.py",
                 "test_pareto_resume.py", "test_input_errors.py", "test_inspect.py", "test_point_rows.py",
                 "test_parallel.py", "test_discrepancy.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: each file's own order is kept
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow study: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def flight_test_cache(tmp_path_factory):
    """A folder of the small flight tests this session generated (studies.small_instances.generate_cached), shared by
    the xdist workers: a test whose generator text another test used copies that flight test instead of simulating
    it again."""
    base = tmp_path_factory.getbasetemp()
    cache = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "flight_tests"
    cache.mkdir(exist_ok=True)
    return cache
