"""A bake-off run's progress, read from its checkpoints as the trainer counts its budget, and its policy."""

import shutil
from pathlib import Path

from learner.core.checkpoint import Counters, checkpoint_path, save_checkpoint
from learner.core.config import TrainConfig
from learner.core.json_file import write_json
from learner.evaluation.selection import RECORD, Validated, choice_record
from learner.experiments.bakeoff_runs import Run, evaluate_run
from learner.experiments.run_archive import EVALUATION_FILE, read_json
from tests.learner.tiny_checkpoint import save_untrained_checkpoint


def test_a_run_with_no_checkpoint_has_done_nothing(tmp_path):
    assert Run.in_bakeoff(tmp_path, "currot", 0).steps_done() == 0


def test_steps_done_count_the_budget_as_the_trainer_does(tmp_path):
    """A budget of trained steps leaves score-only steps out, so a robust PLR run that the trainer
    ended at its budget reads as finished, not as one to resume with steps still to go."""
    counters = Counters(iteration=3, steps=1_500, score_only_steps=500)
    trained = Run.in_bakeoff(tmp_path, "robust-plr", 0)
    played = Run.in_bakeoff(tmp_path, "robust-plr", 1)
    save_checkpoint(trained.directory, {}, counters, TrainConfig(total_steps=1_000, budget_steps="trained"))
    save_checkpoint(played.directory, {}, counters, TrainConfig(total_steps=1_000))
    assert trained.steps_done() == 1_000
    assert played.steps_done() == 1_500


def test_a_validated_run_is_evaluated_on_the_policy_it_chose(tmp_path):
    run = Run.in_bakeoff(tmp_path, "fixed", 0)
    chosen = save_untrained_checkpoint(run.directory)
    final = Path(shutil.copy(chosen, checkpoint_path(run.directory, 1024)))
    candidates = [Validated(chosen, 512, 0.9), Validated(final, 1024, 0.5)]
    write_json(run.directory / RECORD, choice_record(run.directory, candidates, candidates[0], 200, 200_000, 512, 512))
    evaluate_run(run, episodes=1, seed=100_000, processes=1)
    assert read_json(run.directory / EVALUATION_FILE)["checkpoint"] == chosen.name
