"""The modules that decide (issue: tests that pin every promise) and the test files that cover each. A
module's mutants run only these files: the whole suite per mutant would take days on two cores."""

from __future__ import annotations

W, C, P, S = "tests/worker_tests", "tests/coordinator_tests", "tests/protocol_tests", "tests/storage_tests"

# name -> (module, test files); the name is what `--modules` takes and what the JSON reports
TARGETS: dict[str, tuple[str, tuple[str, ...]]] = {
    # fast, pure tests first: with -x a mutant they kill costs seconds; modules whose tests start processes or
    # compile kernels last
    "scoring": ("spinefarm/worker/trial/scoring.py", (f"{W}/test_scoring.py", f"{W}/test_score_units.py")),
    "sampler-paper": ("spinefarm/coordinator/samplers/hill_climb.py", (f"{C}/test_samplers.py",)),
    "sampler-registry": ("spinefarm/coordinator/samplers/registry.py", (f"{C}/test_samplers.py",)),
    # not test_environment.py's search and resume (the record's way into run files, not this module's code):
    # minutes per mutant on two busy cores
    "environment": ("spinefarm/protocol/environment.py",
                    (*(f"{P}/test_environment.py::{t}" for t in (
                        "test_the_record_names_python_packages_cpu_blas_and_commit",
                        "test_differences_name_what_changed_and_nothing_else",
                        "test_the_record_keeps_the_variables_that_steer_blas_and_numba",
                        "test_without_a_checkout_of_its_own_the_commit_is_spinefarm_commit")),
                     f"{P}/test_environment_differences.py", f"{P}/test_environment_sources.py",
                     f"{P}/test_environment_blas.py")),
    "scheduler": ("spinefarm/coordinator/scheduler.py",
                  (f"{C}/test_scheduler.py", f"{C}/test_scheduler_liveness.py")),
    "judge-audit": ("spinefarm/coordinator/ladder/checks.py",
                    (f"{C}/test_check_rules.py", f"{C}/test_check_row_engine.py", f"{C}/test_judge_rules.py",
                     f"{C}/test_best_judged.py", f"{C}/test_opinion.py")),
    # what a set ranks by: the judged figure, the COT factor, the screen's bias the judge measured (docs/distributed.md)
    "ranking": ("spinefarm/storage/ranking.py",
                (f"{C}/test_screen_bias.py", f"{C}/test_best_judged.py", f"{S}/test_judged_cot_ranking.py")),
    # not test_no_locks.py's searches on a file system without locks (minutes per mutant on two busy cores):
    # test_runlock_no_locks.py takes the lock there in one process
    "runlock": ("spinefarm/storage/runlock.py",
                (f"{S}/test_runlock_rules.py", f"{S}/test_runlock_no_locks.py", f"{S}/test_runlock_links.py",
                 f"{S}/test_no_locks.py::test_the_waiver_reads_hdf5s_switch_as_hdf5_does")),
    "robust-scoring": ("spinefarm/protocol/robust.py",
                       (f"{P}/test_robust.py", f"{P}/test_robust_draws.py", f"{P}/test_robust_episode_seeds.py",
                        f"{P}/test_robust_statistic.py",
                        f"{W}/test_robust_scoring.py", f"{W}/test_robust_worlds.py")),
    "robust-worlds": ("spinefarm/worker/trial/robust.py",
                      (f"{W}/test_robust_world_rules.py", f"{W}/test_robust_one_episode.py",
                       f"{W}/test_robust_scoring.py", f"{W}/test_robust_worlds.py")),
    # the rungs' rules on storage alone; the process tests of test_fidelity.py / test_ladder.py (minutes a mutant)
    # hold the same code end to end and are left out
    "ladder": ("spinefarm/coordinator/ladder/rungs.py",
               (f"{C}/test_rung_rules.py", f"{C}/test_promotion_worker.py", *(f"{C}/test_fidelity.py::{t}" for t in (
                   "test_the_best_third_of_a_rung_is_promoted_best_first_and_once",
                   "test_bad_rungs_are_refused_with_what_was_expected",
                   "test_at_the_end_the_best_goes_on_through_rungs_holding_fewer_rows_than_eta",
                   "test_a_search_that_keeps_improving_promotes_about_a_third_and_always_its_best",
                   "test_samplers_see_the_first_rung_only_so_rungs_do_not_change_their_proposals")))),
    # the seam's rules on a run file in-process first (seconds), then the core's message-level tests
    "ladder-seam": ("spinefarm/coordinator/ladder/ladder.py",
                    (f"{C}/test_ladder_seam_fidelity.py", f"{C}/test_ladder_seam_drops.py",
                     f"{C}/test_ladder_seam_audits.py", f"{C}/test_promotion_worker.py",
                     f"{C}/test_core.py", f"{C}/test_unaudited.py", f"{C}/test_opinion.py")),
    "calibration": ("spinefarm/worker/tools/calibrate.py",
                    (f"{W}/test_calibration_figures.py", f"{W}/test_calibration_thresholds.py",
                     f"{W}/test_calibrate_judge.py")),
    # not test_calibrate.py's calibrations and searches: minutes per mutant on two busy cores
    "engine-auto": ("spinefarm/cli/engine_auto.py",
                    ("tests/cli_tests/test_engine_auto.py", "tests/cli_tests/test_engine_auto_request.py")),
    "contact-guard": ("spinefarm/worker/engines/contact_guard.py",
                      (f"{W}/test_mujoco.py::test_auto_segment_contacts_give_the_bits_of_modelled_ones",)),
    "sandbox": ("spinefarm/worker/service/sandbox.py",
                (f"{W}/test_trial_limit_rule.py",
                 f"{W}/test_trial_limit.py::test_a_trial_process_dies_with_its_worker_even_mid_trial")),
    "parent-death": ("spinefarm/worker/service/parent_death.py",
                     (f"{W}/test_parent_death.py",
                      f"{W}/test_trial_limit.py::test_a_trial_process_dies_with_its_worker_even_mid_trial")),
}

# Modules whose every mutant would take hours here (their tests start searches, trial processes or whole
# calibrations): only the functions behind a documented promise are mutated (tests/mutation/lines.py); the
# rest of such a module (process plumbing, caching, messages) is held by its process tests, not measured. Their
# test lists above are the tests that reach those functions (not test_calibrate.py's whole calibrations, nor
# test_trial_limit.py's searches: minutes per mutant here).
FUNCTIONS: dict[str, tuple[str, ...]] = {
    # the thresholds, the ranks behind rho, the judge's step and the key (docs/engines.md)
    "calibration": ("ranks", "spearman", "agreement", "decide", "reference_step", "CalibrationSettings"),
    # when auto calibrates, and the rungs it screens with (docs/engines.md)
    "engine-auto": ("screen_ladder", "wants_auto", "choose_engine"),
    # the wall-clock limit's rule (docs/reliability.md), the name of a trial process's end
    "sandbox": ("TrialLimit", "_exit_text"),
}

# Test files run first with numba's compiler off (NUMBA_DISABLE_JIT=1): a mutant of a numba kernel would
# otherwise be compiled again for every mutant (half a minute or more here). Only if they all pass do the
# module's files above run, compiled (tests/mutation/pytest_exit.py).
NO_JIT: dict[str, tuple[str, ...]] = {
    "contact-guard": (f"{W}/test_segment_distance.py", f"{W}/test_contact_guard.py", f"{W}/test_contact_guard_spin.py",
                      f"{W}/test_mujoco.py::test_segment_distance_agrees_with_dense_sampling",
                      f"{W}/test_mujoco.py::test_the_contact_guard_is_silent_while_segments_are_apart",
                      f"{W}/test_mujoco.py::test_filtered_pairs_pass_through_each_other"),
}

# mutmut's allowance per mutant beyond twice the unmutated tests' time (its --test-time-base), in seconds:
# past it a mutant counts as timed out. A compiled stage that compiles its mutated kernel again needs minutes
# on two busy cores, which must not pass for an endless loop.
TEST_TIME_BASE_S: dict[str, float] = {"contact-guard": 240.0}
