"""Test-time practice's bookkeeping: the per-scene settings and the totals over scenes."""

from __future__ import annotations

from gymnast.envs.tasks import eval_seed
from gymnast.experiment.new_scenes import practice_settings, scenes_for, table, totals
from gymnast.rl.config import RLConfig


def _row(task: str, before: bool, after: bool) -> dict:
    return {"task": task, "seed": eval_seed(0), "updates": 1, "steps": 2, "judged_train_success": [0.5, 0.75],
            "imagined_before": True, "imagined_after": True, "real_before": before, "real_after": after,
            "watch_imagined_success": None, "watch_real_success": None, "watch_false_success": None,
            "reset_frames": 3, "real_interactions": 0, "eval_real_interactions": 40, "watch_real_interactions": 10,
            "wall_s": 60.0}


def test_the_new_scenes_are_the_first_evaluation_seeds_of_each_task():
    assert scenes_for(["reach-v3", "push-v3"], 2) == [("reach-v3", eval_seed(0)), ("reach-v3", eval_seed(1)),
                                                     ("push-v3", eval_seed(0)), ("push-v3", eval_seed(1))]


def test_practice_on_a_scene_keeps_the_recipe_and_evaluates_only_before_and_after():
    recipe = RLConfig(steps=20, starts_per_step=20, group_size=8, lr=3e-5, kl_coef=0.1, freeze=("vision",),
                      fresh_scenes=True, eval_every=10, warmup_steps=5)
    settings = practice_settings(recipe, steps=8, starts_per_step=4)
    assert (settings.steps, settings.starts_per_step, settings.group_size) == (8, 4, 8)
    assert (settings.lr, settings.kl_coef, settings.freeze) == (3e-5, 0.1, ("vision",))
    assert not settings.fresh_scenes and settings.eval_every == 0 and settings.warmup_steps == 1
    assert settings.watch_every == settings.video_every == settings.checkpoint_every == 8


def test_totals_count_the_scenes_practice_won_and_lost():
    rows = [_row("reach-v3", False, True), _row("reach-v3", True, False), _row("push-v3", True, True),
            _row("push-v3", False, True)]
    total = totals(rows)
    assert total["scenes"] == 4 and (total["gained"], total["lost"]) == (2, 1)
    assert (total["real_before"]["success"], total["real_after"]["success"]) == (0.5, 0.75)
    low, high = total["real_after"]["ci"]
    assert low < 0.75 < high
    assert (total["real_interactions"], total["eval_real_interactions"], total["wall_s"]) == (0, 160, 240.0)
    text = "\n".join(table(rows, total))
    assert "real success 50% [" in text and "(2 scenes gained, 1 lost)" in text and text.count("| reach-v3 |") == 2
