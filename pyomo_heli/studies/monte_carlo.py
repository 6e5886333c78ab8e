"""Monte Carlo study: bias and spread of time-domain and multi-objective estimates over noise realizations.

    python studies/monte_carlo.py --realizations 20 --out results/monte_carlo

Each realization adds seeded white noise, at the noise levels of the bundled
flight test (``data/bo105_synthetic.toml``: sensor sigmas; trim sigma and
offset together), to the noise-free bundled data named in the study config
(``studies/monte_carlo.toml``), then solves point A (time domain) and a Pareto
front with its Eq. 11 choice (multi-objective), and the Cramer-Rao standard
errors at both estimates. The table (bias, spread, median CRB per parameter
and estimator) goes to ``summary.csv``/stdout, the figure to
``monte_carlo.png``. Each finished realization is in ``realizations.csv`` at
once; running the same command again continues where it stopped.

Realizations run in worker processes (``--workers``). With a Dask cluster,
``--scheduler ADDRESS`` (or ``--scheduler local`` for a ``LocalCluster``; ``--dask`` is the older name) hands the same
tasks to that cluster (``--workers`` then counts only for ``local``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[2] / "studies"


def main(argv=None) -> int:
    from pyomo_heli.config import ConfigError, load_identification_config
    from pyomo_heli.provenance import ResultsMismatchError
    from pyomo_heli.physics.parameters import bo105
    from pyomo_heli.report.monte_carlo import plot_monte_carlo, summary_markdown
    from pyomo_heli.uncertainty.monte_carlo import ProblemSpec, run_monte_carlo
    from pyomo_heli.flighttest.config import flight_test_noise
    from pyomo_heli.parallel import check_dask_flags, dask_executor

    from .args import nonneg_int, out_folder
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(HERE / "monte_carlo.toml"), help="identification config (clean data)")
    ap.add_argument("--noise-from", default=str(HERE.parent / "data" / "bo105_synthetic.toml"),
                    help="flight-test generator config whose sensor and trim noise levels are used")
    ap.add_argument("--realizations", type=int, default=20)
    ap.add_argument("--seed", type=nonneg_int, default=2026)
    ap.add_argument("--workers", type=nonneg_int, default=None,
                    help="worker processes (default 2; 0: run in this process)")
    ap.add_argument("--time-only", action="store_true", help="time-domain estimates only (no front)")
    ap.add_argument("--scheduler", "--dask", dest="scheduler", metavar="ADDRESS",
                    help="run on a Dask cluster: its scheduler's address, or 'local' for a LocalCluster of --workers "
                         "processes (--dask: the older name)")
    ap.add_argument("--out", default="results/monte_carlo")
    a = ap.parse_args(argv)
    out_folder(ap, a.out)
    if a.scheduler != "local":
        try:
            check_dask_flags(a.workers, a.scheduler)
        except ValueError as exc:
            ap.error(str(exc))
    workers = 2 if a.workers is None else a.workers
    if a.realizations < 2:
        print(f"monte_carlo: --realizations must be at least 2, got {a.realizations}", file=sys.stderr)
        return 2
    try:
        cfg = load_identification_config(a.config)
        sigma, trim_sigma, low_speed = flight_test_noise(a.noise_from)
    except (ConfigError, FileNotFoundError, ValueError) as exc:
        print(f"monte_carlo: {exc}", file=sys.stderr)
        return 2
    # the study solves the two-objective uniform front (ParetoSolver.front): a config asking for more is refused here,
    # not turned into a failed row per realization
    unsupported = ([f"[objectives] use = {list(cfg.objectives)} (the study fits J_time and J_trim)"]
                   if tuple(cfg.objectives) != ("time", "trim") else []) + \
                  ([f"[pareto] placement = {cfg.pareto.placement!r} (the study solves the uniform grid)"]
                   if cfg.pareto.placement != "uniform" else []) + \
                  ([f"[pareto] points = {list(cfg.pareto.grid)} (one count: the front has one bounded objective)"]
                   if cfg.pareto.grid is not None else [])
    if unsupported and not a.time_only:
        print(f"monte_carlo: --config {a.config}: {'; '.join(unsupported)}", file=sys.stderr)
        return 2
    sigma = {o: sigma[o] for o in cfg.nlp.time_outputs}
    trim_sigma = {o: trim_sigma[o] for o in cfg.nlp.trim_outputs}
    truth = dict(bo105())  # the clean data are M0 at the nominal table (data/bo105_clean.toml)
    # --scheduler local: a LocalCluster of --workers processes; an address: that cluster; none: run_monte_carlo's own
    local = a.scheduler == "local"
    try:
        with dask_executor(max(workers, 1) if local else 0, None if local else a.scheduler) as executor:
            res = run_monte_carlo(ProblemSpec.make(a.config), a.realizations, a.seed, sigma, trim_sigma, truth,
                                  out=a.out, multi_objective=not a.time_only, workers=workers, executor=executor,
                                  low_speed=(low_speed[0], {o: s for o, s in low_speed[1].items() if o in sigma}))
    except ResultsMismatchError as exc:  # --out holds another run's realizations
        print(f"monte_carlo: {exc}", file=sys.stderr)
        return 2
    out = Path(a.out)
    plot_monte_carlo(res, out / "monte_carlo.png")
    (out / "summary.md").write_text(summary_markdown(res) + "\n")
    print(summary_markdown(res))
    if not res.estimates["success"].astype(bool).any():  # nothing to summarise: say why, exit 1
        first = res.estimates["status"].iloc[0] if len(res.estimates) else "no row"
        print(f"monte_carlo: no realization succeeded ({len(res.estimates)} rows in {out / 'realizations.csv'}; "
              f"the first: {first})", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
