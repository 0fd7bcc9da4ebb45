"""A bake-off run's progress, read from its checkpoints as the trainer counts its budget."""

from learner.core.checkpoint import Counters, save_checkpoint
from learner.core.config import TrainConfig
from learner.experiments.bakeoff_runs import Run


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
