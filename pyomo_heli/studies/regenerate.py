"""The commands that regenerate ``docs/results``, in order, and what of their output is kept.

    python studies/regenerate_docs.py                       # list every command (nothing is run)
    python studies/regenerate_docs.py --check               # list, and check that every config, script and input exists
    python studies/regenerate_docs.py --run case1 case2     # run these entries into docs/results (their inputs first)
    python studies/regenerate_docs.py --run all --out results/docs_results   # everything, elsewhere (hours)
    python studies/regenerate_docs.py --run case1 --out /tmp/r --compare    # and compare it with docs/results
    python studies/regenerate_docs.py --run held_out --resume   # after an interruption: go on where it stopped

``--compare`` checks every number of the kept files against the committed folder to 1e-6 relative
(``pyomo_heli.studies.compare_results``), prints a table per entry and exits 1 if any differs.

Each entry names a folder of ``docs/results``, the commands that write it (from the checkout root; ``{out}``
is the ``--out`` folder, default ``docs/results``) and the files of it that are committed: after its
commands, every other file of the folder (loop folders of a seeds study, figures no doc shows, generated
flight tests) is deleted, so the regenerated folder holds what the docs show and quote. Entries run in
the order listed; an entry whose input is another entry's folder (a diagnosis of ``case1``, the seeds
studies' ``--existing`` loops) needs that one first: ``--run`` adds those inputs itself. The times are
one core of the project's 2-core machine. The benchmark's ``.txt`` files are its printed output.
"""
from __future__ import annotations

import argparse
import fnmatch
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the checkout: studies/, data/, docs/

IDENTIFY_FILES = ("chosen.json", "front.csv", "identifiability.csv", "metrics.json", "parameters.csv",
                  "parameters.md", "pareto_front.png", "report.md", "time_domain.json", "trim_vs_speed.png",
                  "validation.png")
FRONT_FILES = ("chosen.json", "front.csv", "time_domain.json")
TRI_FILES = ("band_errors.csv", "bode.png", "chosen.json", "front.csv", "frequency_responses.csv",
             "front_projections.png", "parameters_tri.csv", "report_linear.md", "time_domain.json")
LOOP_FILES = ("loop.json", "loop_report.md", "shape_*.json", "iter_*/chosen.json", "iter_*/front.csv",
              "iter_*/time_domain.json")
#: the figures a loop's report shows (``pyomo-heli report-loop`` draws them again from the kept files, no solve)
LOOP_FIGURES = ("loop_trim_vs_speed.png", "loop_trim_forces.png", "loop_validation.png")
SEEDS = "20261123 20261124 20261125 20261126 20261127"
#: held-out effects H1-H13 (the full-size table ``held_out``), H14-H16 (the third blind set, ``held_out_blind3``) and
#: H17-H19 (the fourth, ``held_out_blind4``)
H1_H13 = ("fuselage_download drag_rise canted_tail_rotor vertical_drag control_mixing actuator_lag "
          "accelerometer_filter pitot_downwash tail_stall fuselage_pitch_damping cyclic_gearing static_port_error "
          "rotor_speed_droop")
H14_H16 = "skewed_inflow_gradient cyclic_free_play rotor_pylon_mode"
H17_H19 = "advancing_blade_compressibility fuselage_wake_incidence pitch_rate_damper"
BENCH = "python studies/benchmark.py"
#: the held-out studies' tables, in the order of docs/discovery_results.md (``held_out_summary`` tallies them)
HELD_OUT_TABLES = ("held_out_small", "held_out_small_blind4", "held_out_small_extended", "noise_only", "held_out",
                   "held_out_blind3", "held_out_blind4", "held_out_extended")
HELD_OUT = "python studies/held_out_effects.py"
#: the short generic library of tests/test_discovery.py (its small instances)
TEST_GENERIC = "dM_one dM_mu2 dM_bump00 dM_bump05 dM_bump10 dX_mu4 dZ_one dZ_bump00 TAS_scale"
#: the held-out rows of the extended family's table that seed 20261123's collective gain (col_scale) describes
SEED23_COL_SCALE = "skewed_inflow_gradient vertical_drag advancing_blade_compressibility"
#: record-rate measured inputs with AR(4) input errors and each record's reference error (docs/generic_term_level.md)
RECORD_INPUTS = "data.resample_inputs=record objectives.input_error_ar=4 objectives.input_reference_error=true"
SMALL = "--config studies/held_out_small.toml --data-config studies/held_out_small_gen.toml"


#: the settings a regenerated held-out table is made with where held_out_discovery.toml still pins the older ones
#: (raw-LR ranking, the residual analysis against the resampled inputs' replay) for the tables not yet regenerated
RECORD_P = "--set loop.generic_rank=p diagnosis.replay=record"


def reanalysed(folder: str, flags: str = "") -> tuple[str, str]:
    """The two commands that follow a held-out study's runs, as the committed tables were made: the residual
    analysis of the kept model made again where the table holds it (``--reanalyse``, with the runs' ``flags``:
    config, data config, family; docs/discovery_results.md, "The input path on the kept models"), then the shape
    columns and criterion re-scored from the terms the table prints (``--rescore``, with the same flags: the data config
    decides the validation records a signature is judged on)."""
    flags = f" {flags}" if flags else ""
    return (f"{HELD_OUT} --reanalyse {{out}}/{folder}/scratch{flags} --out {{out}}/{folder}",
            f"{HELD_OUT} --rescore{flags} --out {{out}}/{folder}")


@dataclass(frozen=True)
class Entry:
    """One folder of docs/results: its commands, the files kept, the entries it reads, about how long."""

    folder: str
    commands: tuple[str, ...]
    keep: tuple[str, ...]
    needs: tuple[str, ...] = ()
    minutes: float = 1.0
    stdout: dict = field(default_factory=dict)  # command index -> file (in the folder) for its printed output
    text: tuple[str, ...] = ()  # printed outputs (globs) holding no timings: --compare reads them line by line


ENTRIES: tuple[Entry, ...] = (
    Entry("case1", ("pyomo-heli identify studies/case1.toml --out {out}/case1 --cold-check --restart",),
          IDENTIFY_FILES, minutes=6),
    Entry("case2", ("pyomo-heli identify studies/case2.toml --out {out}/case2 --restart",),
          tuple(f for f in IDENTIFY_FILES if f != "validation.png"), minutes=1.5),  # Case 1's shows the picture
    Entry("case1_project", ("pyomo-heli identify studies/case1_project.toml --out {out}/case1_project "
                            "--no-report --restart",), FRONT_FILES, minutes=1.5),
    Entry("case2_project", ("pyomo-heli identify studies/case2_project.toml --out {out}/case2_project "
                            "--no-report --restart",), FRONT_FILES, minutes=1.5),
    Entry("case1_diagnosis", ("pyomo-heli diagnose {out}/case1 --out {out}/case1_diagnosis --no-residuals",),
          ("diagnosis.md", "diagnosis.json", "diagnosis_trim.png", "diagnosis_trim_forces.png", "implied_forces.csv"),
          needs=("case1",), minutes=1),
    Entry("case2_diagnosis", ("pyomo-heli diagnose {out}/case2 --out {out}/case2_diagnosis --no-residuals",),
          ("diagnosis.md",), needs=("case2",), minutes=1),
    Entry("case2_uncertainty", ("pyomo-heli uncertainty studies/case2.toml --results {out}/case2 "
                                "--out {out}/case2_uncertainty --points chosen",),
          FRONT_FILES + ("identifiability.csv",), needs=("case2",), minutes=1),
    # Case 1 tri-objective, measured against the bi-objective Case 1 in the same process (issue 31: < 3x)
    Entry("case1_tri", (f"{BENCH} --tri-vs-bi --out {{out}}/case1_tri/timing --tri-out {{out}}/case1_tri",
                        "pyomo-heli report-linear studies/case1_tri.toml --out {out}/case1_tri"),
          TRI_FILES + ("tri_vs_bi.txt", "timing/tri_vs_bi.json"), minutes=4, stdout={0: "tri_vs_bi.txt"}),
    Entry("case2_tri", ("pyomo-heli identify studies/case2_tri.toml --out {out}/case2_tri --restart",), TRI_FILES,
          minutes=15),
    Entry("linear_checks", ("python studies/linear_checks.py --dataset data/bo105_clean --out {out}/linear_checks",),
          ("linear_checks.md", "linear_checks.json"), minutes=0.2),
    Entry("close_loop", ("pyomo-heli close-loop studies/close_loop.toml --out {out}/close_loop --restart",),
          LOOP_FILES + LOOP_FIGURES, minutes=5),
    Entry("close_loop_eiv", ("pyomo-heli close-loop studies/close_loop_eiv.toml --out {out}/close_loop_eiv "
                             "--restart",), LOOP_FILES + LOOP_FIGURES, minutes=6),
    Entry("close_loop_seeds", (f"python studies/close_loop_seeds.py --seeds {SEEDS} --existing {{out}}/close_loop "
                               f"--out {{out}}/close_loop_seeds",),
          ("seeds.md", "seeds.csv"), needs=("close_loop",), minutes=25),
    Entry("close_loop_seeds_eiv", (f"python studies/close_loop_seeds.py --config studies/close_loop_eiv.toml "
                                   f"--seeds {SEEDS} --existing {{out}}/close_loop_eiv "
                                   f"--out {{out}}/close_loop_seeds_eiv",),
          ("seeds.md", "seeds.csv"), needs=("close_loop_eiv",), minutes=30),
    Entry("envelope_validation", ("python studies/envelope_validation.py --loops {out}/close_loop_eiv "
                                  + " ".join(f"{{out}}/close_loop_seeds_eiv/loop_{s}" for s in SEEDS.split())
                                  + " {out}/close_loop "
                                  + " ".join(f"{{out}}/close_loop_seeds/loop_{s}" for s in SEEDS.split())
                                  + " --out {out}/envelope_validation",),
          ("envelope_validation.md",), needs=("close_loop_seeds", "close_loop_seeds_eiv"), minutes=2),
    Entry("innovation_check", ("python studies/innovation_check.py --loop {out}/close_loop_eiv "
                               "--out {out}/innovation_check",), ("summary.csv",), needs=("close_loop_eiv",),
          minutes=2),
    # docs/diagnosis.md: the truth model's innovations on the bundled flight test and the seeds studies' five other
    # noise realisations of it, pooled
    Entry("innovation_check_seeds", (
        *(f"pyomo-heli generate-data --config data/bo105_synthetic.toml --seed {s} "
          f"--out {{out}}/innovation_check_seeds/data/{s} --force" for s in SEEDS.split()),
        "python studies/innovation_check.py --dataset data/bo105_synthetic "
        + " ".join(f"{{out}}/innovation_check_seeds/data/{s}" for s in SEEDS.split())
        + " --out {out}/innovation_check_seeds"), ("summary.csv", "pooled.csv"), minutes=4),
    Entry("score_test_level", (
        "python studies/score_test_level.py --seeds 101-200 --out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-200 --identification oe --out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-140 --truth wake --out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-140 --truth wake --identification oe "
        "--out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-200 --variance white --out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-140 --truth wake --variance white --out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-200 --variance white_offsets --out {out}/score_test_level",
        "python studies/score_test_level.py --seeds 101-140 --truth wake --variance white_offsets "
        "--out {out}/score_test_level"),
        ("*/summary*.csv",), minutes=60),
    Entry("validation_test_level", ("python studies/validation_test_level.py --seeds 20261122-20261147 "
                                    "--out {out}/validation_test_level",),
          ("summary.csv", "summary.md"), minutes=30),
    # the time-domain twist with the truth's model form, with and without the noise on the measured inputs
    Entry("input_noise_check", ("python studies/input_noise_check.py --seeds 20261122,20261125,20261126,20261127 "
                                "--config studies/close_loop.toml --out {out}/input_noise_check",),
          ("summary.csv", "summary.md"), minutes=70),
    # the record-bias test's level as configured and against the record-rate replay
    *(Entry(f"record_bias_level{suffix}", (f"python studies/record_bias_level.py --seeds 20261122-20261161{flag} "
                                           f"--out {{out}}/record_bias_level{suffix}",),
            ("summary.csv", "summary.md"), minutes=20)
      for suffix, flag in (("", ""), ("_record", " --replay record"))),
    # the input path's level as configured, with the inputs picked, and against the record-rate replay
    *(Entry(f"input_path_level{suffix}", (f"python studies/input_path_level.py --seeds 20261122-20261161{flag} "
                                          f"--out {{out}}/input_path_level{suffix}",),
            ("summary.csv", "summary.md"), minutes=20)
      for suffix, flag in (("", ""), ("_sample", " --resample-inputs sample"), ("_record", " --replay record"),
                           ("_extended", " --input-path-family extended"),
                           ("_extended_record", " --input-path-family extended --replay record"))),
    # docs/real_data.md: the trim-only score test's level and power on synthetic trim sets like the real ones
    Entry("trim_score_level", ("python studies/score_test_level.py --trims --seeds 0-19 --truth m0",
                               "python studies/score_test_level.py --trims --seeds 0-9 --truth wake"),
          ("m0.txt", "wake.txt"), minutes=1.5, stdout={0: "m0.txt", 1: "wake.txt"},
          text=("*.txt",)),
    # docs/discovery.md, "Which test decides": the test library's generic terms on the small instance's M0 + noise,
    # with the input errors estimated (the corrected LR decides) and in output error (the score test's own p does)
    Entry("deciding_test", tuple(
        f"python studies/generic_term_level.py --seeds 21-30 --terms {TEST_GENERIC} --config "
        f"studies/held_out_small.toml --data-config studies/held_out_small_gen.toml{flag} --out {{out}}/deciding_test"
        for flag in ("", " --identification oe")),
        ("summary.csv", "summary.md", "oe/summary.csv", "oe/summary.md"), minutes=4),
    # the input scale factors' NLP estimates when nothing is missing (the held-out rows' col_scale)
    Entry("generic_term_level", (
        "python studies/generic_term_level.py --seeds 20261122-20261141 --out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --exact-inputs --out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261131 --exact-inputs --identification oe "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --input-sigma-scale 1.7 "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --resample-inputs sample "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --resample-inputs record "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --resample-inputs record --input-error-ar 2 "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --resample-inputs record --input-error-ar 4 "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --resample-inputs record --input-error-ar 4 "
        "--input-reference-error --out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --input-reference-error "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --input-error-ar 4 --input-reference-error "
        "--out {out}/generic_term_level",
        "python studies/generic_term_level.py --seeds 20261122-20261141 --output-error-ar 2 "
        "--out {out}/generic_term_level"),
        ("summary.csv", "summary.md", "exact_inputs/summary.csv", "exact_inputs/summary.md",
         "exact_inputs_oe/summary.csv", "exact_inputs_oe/summary.md", "input_sigma_x1.7/summary.csv",
         "input_sigma_x1.7/summary.md", "inputs_sample/summary.csv", "inputs_sample/summary.md",
         "inputs_record/summary.csv", "inputs_record/summary.md", "inputs_record_input_error_ar2/summary.csv",
         "inputs_record_input_error_ar2/summary.md", "inputs_record_input_error_ar4/summary.csv",
         "inputs_record_input_error_ar4/summary.md", "inputs_record_input_error_ar4_input_reference_error/summary.csv",
         "inputs_record_input_error_ar4_input_reference_error/summary.md", "input_reference_error/summary.csv",
         "input_reference_error/summary.md", "input_error_ar4_input_reference_error/summary.csv",
         "input_error_ar4_input_reference_error/summary.md", "output_error_ar2/summary.csv",
         "output_error_ar2/summary.md"), minutes=540),
    Entry("input_path", ("python studies/input_path_check.py --seeds 1 --out {out}/input_path",
                         "python studies/input_path_check.py --effects none --seeds 5 --out {out}/input_path"),
          ("input_path.csv", "input_path.md"), minutes=13),
    Entry("monte_carlo", ("python studies/monte_carlo.py --realizations 20 --out {out}/monte_carlo",),
          ("monte_carlo.json", "monte_carlo.png", "realizations.csv", "summary.csv", "summary.md"), minutes=5),
    Entry("multistart_case1", ("pyomo-heli multistart studies/multistart_case1.toml --starts 20 --seed 1 "
                               "--out {out}/multistart_case1 --restart",), ("multistart.json", "starts.csv"),
          minutes=2),
    Entry("multistart_case1_eps", ("pyomo-heli multistart studies/multistart_case1.toml --starts 20 --seed 1 "
                                   "--epsilon 0.2008495658274336 --out {out}/multistart_case1_eps --restart",),
          ("multistart.json", "starts.csv"), minutes=3),
    Entry("held_out_small", (f"{HELD_OUT} --seeds 1 --effects {H1_H13} {H14_H16} none {SMALL} "
                             "--workers 2 --out {out}/held_out_small", *reanalysed("held_out_small", SMALL)),
          ("held_out.csv", "held_out.md"), minutes=15),
    Entry("held_out_small_blind4", (f"{HELD_OUT} --seeds 1 --effects {H17_H19} {SMALL} "
                                    "--out {out}/held_out_small_blind4",
                                    *reanalysed("held_out_small_blind4", SMALL)),
          ("held_out.csv", "held_out.md"), minutes=3),
    # the small instance with the extended family, every held-out effect and M0 + noise
    Entry("held_out_small_extended", (f"{HELD_OUT} --seeds 1 --effects {H1_H13} {H14_H16} {H17_H19} none {SMALL} "
                                      "--generic-family extended --workers 2 --out {out}/held_out_small_extended",
                                      *reanalysed("held_out_small_extended", f"{SMALL} --generic-family extended")),
          ("held_out.csv", "held_out.md"), minutes=20),
    Entry("noise_only", (f"{HELD_OUT} --effects none --seeds 5 {RECORD_P} --workers 2 --out {{out}}/noise_only",
                         *reanalysed("noise_only", RECORD_P)),
          ("held_out.csv", "held_out.md"), minutes=140),
    Entry("held_out", (f"{HELD_OUT} --seeds 3 --effects {H1_H13} {RECORD_P} --workers 2 --out {{out}}/held_out",
                       f"{HELD_OUT} --bundled {RECORD_P} --out {{out}}/held_out",
                       *reanalysed("held_out", RECORD_P)),
          ("held_out.csv", "held_out.md", "bundled/cost.json"), minutes=360),
    Entry("held_out_extended", (
        f"{HELD_OUT} --seeds 3 --effects fuselage_pitch_damping cyclic_gearing "
        "control_mixing --generic-family extended --out {out}/held_out_extended --workers 2",
        f"{HELD_OUT} --effects none --seeds 5 --generic-family extended "
        "--out {out}/held_out_extended --workers 2",
        f"{HELD_OUT} --bundled --generic-family extended --out {{out}}/held_out_extended",
        f"{HELD_OUT} --seeds 3 --effects pitch_rate_damper fuselage_wake_incidence tail_stall "
        "vertical_drag accelerometer_filter skewed_inflow_gradient canted_tail_rotor advancing_blade_compressibility "
        "drag_rise pitot_downwash fuselage_download rotor_speed_droop static_port_error actuator_lag rotor_pylon_mode "
        "cyclic_free_play --generic-family extended --out {out}/held_out_extended --workers 2",
        *reanalysed("held_out_extended", "--generic-family extended")),
        ("held_out.csv", "held_out.md", "bundled/cost.json"), minutes=990),
    # the control family (extended + control-path feedback) on pitch_rate_damper; written after those rows failed
    Entry("held_out_control", (
        f"{HELD_OUT} --seeds 2 --effects pitch_rate_damper --generic-family control {RECORD_P} "
        "--out {out}/held_out_control --workers 2",
        f"{HELD_OUT} --seeds 1 --effects none --generic-family control {RECORD_P} "
        "--out {out}/held_out_control", *reanalysed("held_out_control", f"--generic-family control {RECORD_P}")),
        ("held_out.csv", "held_out.md"), minutes=50),
    # the blind sets (as held_out) are ranked by the deciding p and analysed against the record-rate replay (the
    # defaults), not as the held_out_discovery.toml pins have the others
    Entry("held_out_blind3", (f"{HELD_OUT} --seeds 3 --effects {H14_H16} {RECORD_P} --workers 2 "
                              "--out {out}/held_out_blind3", *reanalysed("held_out_blind3", RECORD_P)),
          ("held_out.csv", "held_out.md"), minutes=90),
    Entry("held_out_blind4", (f"{HELD_OUT} --seeds 3 --effects {H17_H19} {RECORD_P} --workers 2 "
                              "--out {out}/held_out_blind4", *reanalysed("held_out_blind4", RECORD_P)),
          ("held_out.csv", "held_out.md"), minutes=140),
    # docs/generic_term_level.md, "Why the study configs keep projected inputs": the extended family's seed-23 rows
    # that col_scale describes (and M0 + noise of that seed), with the study configs' projected inputs and with
    # record-rate inputs, AR(4) input errors and each record's reference error; both ranked by the deciding p
    *(Entry(f"record_inputs/{name}", (
        f"{HELD_OUT} --seeds 1 --first-seed 1 --effects {SEED23_COL_SCALE} none --generic-family extended "
        f"{flags} --workers 2 --out {{out}}/record_inputs/{name}",
        *reanalysed(f"record_inputs/{name}", f"--generic-family extended {flags}")),
        ("held_out.csv", "held_out.md"), minutes=minutes)
      for name, flags, minutes in (("projected", RECORD_P, 45), ("record", f"{RECORD_P} {RECORD_INPUTS}", 120))),
    # the input path's extended dictionary on the kept models of the standard family's full-size rows, reanalysed
    Entry("input_path_extended", tuple(
        f"{HELD_OUT} --reanalyse {{out}}/input_path_extended/scratch --rows "
        f"{{out}}/{t}/held_out.csv --input-path-family extended {RECORD_P} --out {{out}}/input_path_extended/{t}"
        for t in ("held_out", "held_out_blind3", "noise_only")),
        tuple(f"{t}/held_out.{x}" for t in ("held_out", "held_out_blind3", "noise_only") for x in ("csv", "md")),
        needs=("held_out", "held_out_blind3", "noise_only"), minutes=70),
    Entry("held_out_summary", (f"{HELD_OUT} --summary " + " ".join(
        f"{{out}}/{f}" for f in HELD_OUT_TABLES) + " --out {out}/held_out_summary",),
          ("summary.md",), needs=HELD_OUT_TABLES, minutes=0.1),
    Entry("bo105_flight_trims", ("pyomo-heli trim-loop studies/bo105_flight_trims.toml "
                                 "--out {out}/bo105_flight_trims",),
          ("report.md", "trim_curves.png", "trim_loop.json", "trim_residuals.png"), minutes=0.2),
    # docs/performance.md, "Scaling": iterations unscaled against scaled (the IDAES Scaler), three instances and the
    # whole Case 1 front (its unscaled run is docs/results/case1/front.csv)
    Entry("scaling", (
        f"{BENCH} --no-front --no-shooting --compare-scaling --out {{out}}/scaling/scaling_case1.json",
        f"{BENCH} --config tests/configs/small_case1_noisy.toml --no-front --no-shooting --compare-scaling "
        "--out {out}/scaling/scaling_small_noisy.json",
        f"{BENCH} --quick --compare-scaling --scaling-points 4 --out {{out}}/scaling/scaling_quick.json",
        "pyomo-heli identify studies/case1_scaled.toml --out {out}/scaling/case1_scaled --cold-check --restart "
        "--no-report --uncertainty none"),
        ("scaling_case1.json", "scaling_case1.txt", "scaling_small_noisy.json", "scaling_small_noisy.txt",
         "scaling_quick.json", "scaling_quick.txt", "case1_scaled/front.csv", "case1_scaled/chosen.json"),
        minutes=6, stdout={0: "scaling_case1.txt", 1: "scaling_small_noisy.txt", 2: "scaling_quick.txt"}),
    Entry("benchmark", (
        f"{BENCH} --size 1,2,4,8 --repeat 3 --shooting rk4 --shooting-max-sims 0 --compare-nl-route "
        "--out {out}/benchmark/benchmark_case1_all.json",
        f"{BENCH} --size 1,2,4,8 --no-front --no-shooting --repeat 3 "
        "--out {out}/benchmark/benchmark_scaling_full.json",
        f"{BENCH} --no-front --shooting rk4-casadi --shooting-max-sims 0 --compare-nl-route "
        "--out {out}/benchmark/benchmark_case1_shooting_casadi_point_rows.json",
        f"{BENCH} --size 1,2,4,8 --no-front --no-shooting --max-duration 1.5 --repeat 3 "
        "--out {out}/benchmark/benchmark_scaling_cropped_gather.json"),
        ("*.json", "*.txt"), minutes=45,
        stdout={0: "benchmark_case1_all.txt", 1: "benchmark_scaling_full.txt",
                2: "benchmark_case1_shooting_casadi_point_rows.txt", 3: "benchmark_scaling_cropped_gather.txt"}),
)
BY_NAME = {e.folder: e for e in ENTRIES}


def argv_of(command: str, out: str) -> list[str]:
    """The command as an argument list for this interpreter (``pyomo-heli`` = ``python -m pyomo_heli.cli``)."""
    args = shlex.split(command.format(out=out))
    if args[0] == "pyomo-heli":
        return [sys.executable, "-m", "pyomo_heli.cli", *args[1:]]
    if args[0] == "python":
        return [sys.executable, *args[1:]]
    raise ValueError(f"cannot run {command!r}")


def with_inputs(names: list[str]) -> list[Entry]:
    """The named entries and, before them, the entries they read, in the order of :data:`ENTRIES`."""
    wanted: set[str] = set()

    def add(name: str) -> None:
        if name not in wanted:
            wanted.add(name)
            for n in BY_NAME[name].needs:
                add(n)

    for n in names:
        add(n)
    return [e for e in ENTRIES if e.folder in wanted]


def problems(entry: Entry, out: str) -> list[str]:
    """What is wrong with an entry's commands without running them: a config or script that is missing, or
    options that ``pyomo-heli``'s own parser refuses."""
    import contextlib
    import io

    from ..cli import build_parser

    missing = []
    for command in entry.commands:
        args = shlex.split(command.format(out=out))
        for a in args:
            if a.endswith((".toml", ".py")) and not (ROOT / a).is_file():
                missing.append(f"{entry.folder}: {a} not found")
        if args[0] == "pyomo-heli":
            err = io.StringIO()
            try:
                with contextlib.redirect_stderr(err):
                    build_parser().parse_args(args[1:])
            except SystemExit:
                missing.append(f"{entry.folder}: {command}: {err.getvalue().strip().splitlines()[-1]}")
    return missing


def prune_matches(rel: str, keep: tuple[str, ...]) -> bool:
    """Whether the file ``rel`` (a path relative to its entry's folder) is one of the kept ones."""
    return any(fnmatch.fnmatchcase(rel, k) for k in keep)


def prune(folder: Path, keep: tuple[str, ...]) -> list[Path]:
    """Delete every file of ``folder`` that matches none of ``keep`` (globs relative to it), then empty folders."""
    removed = []
    for f in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = f.relative_to(folder).as_posix()
        if not prune_matches(rel, keep):
            f.unlink()
            removed.append(f)
    for d in sorted((p for p in folder.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
        if not any(d.iterdir()):
            d.rmdir()
    return removed


PROGRESS = ".regenerate_progress.json"  # in the --out root while a --run is unfinished: the entries it finished


def run(entries: list[Entry], out: str, resume: bool = False) -> None:
    """Run ``entries`` into ``out``, then prune each folder to its committed files. Each finished entry is recorded
    (with its commands) in ``out/.regenerate_progress.json``, which the last prune removes. With ``resume`` a
    recorded entry with the same commands is skipped and the others run into their folders as an interrupted run
    left them, so that each study skips the cases it finished; without it every folder is written afresh."""
    import json
    import shutil

    root = Path(out) if Path(out).is_absolute() else ROOT / out
    progress = root / PROGRESS
    try:
        finished = json.loads(progress.read_text()) if resume and progress.is_file() else {}
    except ValueError:
        raise SystemExit(f"--resume: {progress} is damaged; remove it (or run without --resume)") from None
    for e in entries:
        start = time.perf_counter()
        folder = root / e.folder
        if resume and finished.get(e.folder) == list(e.commands):
            print(f"[{e.folder}] finished by the interrupted run: skipped (--resume)", flush=True)
            continue
        finished.pop(e.folder, None)
        if folder.is_dir() and not resume:  # written afresh: `uncertainty --out` refuses a folder of other results
            shutil.rmtree(folder)
        for i, command in enumerate(e.commands):
            print(f"[{e.folder}] {command.format(out=out)}", flush=True)
            if i in e.stdout:
                folder.mkdir(parents=True, exist_ok=True)  # under the checkout, as the commands' own --out
                with open(folder / e.stdout[i], "w") as fh:
                    proc = subprocess.run(argv_of(command, out), cwd=ROOT, stdout=fh)
            else:
                proc = subprocess.run(argv_of(command, out), cwd=ROOT)
            if proc.returncode != 0:
                raise SystemExit(f"[{e.folder}] failed with exit status {proc.returncode}: {command.format(out=out)}")
        print(f"[{e.folder}] done in {(time.perf_counter() - start) / 60:.1f} min (estimate {e.minutes:g})", flush=True)
        finished[e.folder] = list(e.commands)
        root.mkdir(parents=True, exist_ok=True)
        progress.write_text(json.dumps(finished, indent=1))
    for e in entries:  # last, so that later entries could read the loops and data of earlier ones
        removed = prune(root / e.folder, e.keep)
        print(f"[{e.folder}] kept the committed files, removed {len(removed)} others", flush=True)
    progress.unlink(missing_ok=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", nargs="+", metavar="FOLDER", help="run these entries (or 'all') with their inputs")
    ap.add_argument("--resume", action="store_true",
                    help="with --run: skip the entries an interrupted run into the same --out finished and run the "
                         "others into their folders as left (each study skips its finished cases); without it "
                         "every folder is written afresh")
    ap.add_argument("--check", action="store_true", help="also check that every named config and script exists")
    ap.add_argument("--out", default="docs/results",
                    help="results root, relative to the checkout (default docs/results)")
    ap.add_argument("--compare", nargs="*", metavar="FOLDER",
                    help="compare the --out folders of the --run entries (or of these) with --reference, "
                         "every number to 1e-6 relative; exit 1 if one differs")
    ap.add_argument("--reference", default="docs/results",
                    help="committed results root to compare with, relative to the checkout (default docs/results)")
    a = ap.parse_args(argv)
    reference = Path(a.reference) if Path(a.reference).is_absolute() else ROOT / a.reference
    if a.compare is not None and not reference.is_dir():  # a missing root is bad input, not "differs"
        ap.error(f"--reference {a.reference}: no such folder")
    if a.resume and not a.run:
        ap.error("--resume: give --run with the entries to resume")
    if a.compare and a.run:
        ap.error("--compare: name the folders with --run, or (without --run) with --compare, not both")
    if a.compare is not None and not a.run:
        unknown = [n for n in a.compare if n not in BY_NAME]
        if unknown or not a.compare:
            ap.error(f"--compare: unknown folder {unknown[0]!r}" if unknown else "--compare: name the folders "
                     "to compare (or give --run)")
        return compare([BY_NAME[n] for n in a.compare], a.out, a.reference)
    if a.run:
        unknown = [n for n in a.run if n != "all" and n not in BY_NAME]
        if unknown:
            ap.error(f"--run: unknown folder {unknown[0]!r}; one of {', '.join(BY_NAME)} or all")
        entries = list(ENTRIES) if "all" in a.run else with_inputs(a.run)
    else:
        entries = list(ENTRIES)
    missing = [p for e in entries for p in problems(e, a.out)] if (a.check or a.run) else []
    for e in entries:
        print(f"# {a.out}/{e.folder}  (about {e.minutes:g} min; keeps {', '.join(e.keep)})")
        for command in e.commands:
            print("    " + command.format(out=a.out))
    print(f"# {len(entries)} folders, about {sum(e.minutes for e in entries) / 60:.1f} h on one core")
    if missing:
        print("\n".join(missing), file=sys.stderr)
        return 2
    if a.run:
        run(entries, a.out, resume=a.resume)
        if a.compare is not None:
            return compare([BY_NAME[n] for n in a.run] if "all" not in a.run else list(ENTRIES), a.out, a.reference)
    return 0


def compare(entries: list[Entry], out: str, reference: str) -> int:
    """Print the comparison of each entry's ``out`` folder with its ``reference`` one; 1 if any differs."""
    from .compare_results import compare_folder, table

    def root(p: str) -> Path:
        return Path(p) if Path(p).is_absolute() else ROOT / p

    roots = (reference.rstrip("/"), out.rstrip("/")) if reference.rstrip("/") != out.rstrip("/") else None
    results = {e.folder: compare_folder(root(reference) / e.folder, root(out) / e.folder, e.keep, e.text, roots)
               for e in entries}
    print(table(results), flush=True)
    return 0 if all(c.ok for c in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
