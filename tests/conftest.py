import os

# One BLAS thread per test process, set before numpy loads. `pytest -n 2` runs two workers on CI's two cores; each
# worker's OpenBLAS would start a thread per core and spin-wait on the other's core (measured on one
# identification fixture: 61 s of system time in 93 s without this, 11 s with it).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run paper-scale slow studies")


def pytest_collection_modifyitems(config, items):
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
