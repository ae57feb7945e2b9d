"""The per-frame judge: success at any frame, balanced frame batches, a threshold chosen on
validation scenes only, and checkpoints of either judge kind."""

import dataclasses
import json

import pytest
import torch

from gymnast.data.lerobot import EpisodeDataset
from gymnast.reward.judges.frames import FrameJudge
from gymnast.reward.judges.base import JudgeConfig
from gymnast.reward.judges.measure import choose_threshold, evaluate_judge, roc_readout
from gymnast.reward.judges.train import (HARD_CANDIDATES, JUDGE_PRESETS, FramePool, JudgeTrainConfig, load_judge,
                                         split_scenes, train_judge)
from gymnast.reward.judges.videos import Video, judge_cases

DEBUG = dataclasses.replace(JUDGE_PRESETS["debug"], heldout_fraction=0.25, validation_fraction=0.2)


def video(shows: list[bool], value: int = 0) -> Video:
    """A (T+1)-frame video whose frames are filled with `value` + their index, with per-frame success."""
    shows_t = torch.tensor([False, *shows])
    frames = (torch.arange(len(shows_t)) + value).clamp(max=255).to(torch.uint8)[:, None, None, None].expand(-1, 8, 8, 3)
    return Video(frames.contiguous(), shows_t.cummax(0).values, shows_t, "reach the goal", imagined=False,
                 progress=shows_t.float())


class Brightness:
    """A stand-in judge whose P(success) of a video is its last frame's brightness / 255."""

    def probability(self, videos: torch.Tensor, instructions) -> torch.Tensor:
        return videos[:, -1].float().mean(dim=(1, 2, 3)) / 255


def test_a_video_succeeds_where_its_most_convincing_frame_does():
    judge = FrameJudge(JudgeConfig(width=16, image_size=16, threshold=0.7)).eval()
    videos = torch.randint(0, 255, (2, 5, 16, 16, 3), dtype=torch.uint8)
    per_frame = judge.frame_probabilities(videos, ["open the drawer"] * 2)
    assert per_frame.shape == (2, 5) and (per_frame[:, 0] == 0).all()  # nothing is done at the start
    assert torch.allclose(judge.probability(videos, ["open the drawer"] * 2), per_frame.max(dim=1).values)
    with torch.no_grad():
        judge.head[-1].bias.fill_(-30.0)  # every frame: certainly not
    assert (judge.score(videos, ["open the drawer"] * 2) == 0).all()
    with torch.no_grad():
        judge.head[-1].bias.fill_(30.0)
    assert (judge.score(videos, ["open the drawer"] * 2) == 1).all()
    with pytest.raises(ValueError, match=r"\(B, T, H, W, 3\) uint8"):
        judge.frame_probabilities(videos.float(), ["x"] * 2)


def test_a_success_must_hold_for_the_judges_steps_unless_the_video_ends_on_it():
    from gymnast.reward.judges.frames import held_probability

    p = torch.tensor([[0.0, 0.9, 0.1, 0.1, 0.1, 0.1],    # one frame's flash, denied by those after it
                      [0.0, 0.1, 0.8, 0.7, 0.9, 0.2],    # three steps in a row, then undone
                      [0.0, 0.1, 0.1, 0.1, 0.1, 0.6]])   # the last frame: nothing shows it undone
    assert held_probability(p, 1).tolist() == pytest.approx([0.9, 0.9, 0.6])
    assert held_probability(p, 3).tolist() == pytest.approx([0.1, 0.7, 0.6])
    assert held_probability(p, 4).tolist() == pytest.approx([0.1, 0.2, 0.6])
    loop = [max(min(row[t: t + 3] + [row[-1]] * max(0, t + 3 - len(row))) for t in range(len(row))) for row in p.tolist()]
    assert held_probability(p, 3).tolist() == pytest.approx(loop)  # against a loop over the windows
    judge = FrameJudge(JudgeConfig(width=16, image_size=16, hold_steps=3)).eval()
    videos = torch.randint(0, 255, (2, 6, 16, 16, 3), dtype=torch.uint8)
    per_frame = judge.frame_probabilities(videos, ["open the drawer"] * 2)
    assert torch.equal(judge.probability(videos, ["open the drawer"] * 2), held_probability(per_frame, 3))
    with pytest.raises(ValueError, match="hold_steps must be at least 1"):
        JudgeConfig(hold_steps=0)


def test_a_judge_saved_before_the_hold_rule_believes_one_frame_and_new_ones_hold_their_steps(tiny_dataset, tmp_path):
    spec = FrameJudge(JudgeConfig(width=16, image_size=16, hold_steps=4)).spec()
    assert FrameJudge.from_spec(spec).config.hold_steps == 4
    assert FrameJudge.from_spec({k: v for k, v in spec.items() if k != "hold_steps"}).config.hold_steps == 1
    train_judge(tiny_dataset, tmp_path / "judge", dataclasses.replace(DEBUG, hold_steps=3), progress=False)
    assert load_judge(tmp_path / "judge").config.hold_steps == 3
    # Fine-tuning a judge that held another number of steps: the rule is the new run's, not architecture.
    tuned = dataclasses.replace(DEBUG, hold_steps=1, init=tmp_path / "judge", steps=2)
    train_judge(tiny_dataset, tmp_path / "tuned", tuned, progress=False)
    assert load_judge(tmp_path / "tuned").config.hold_steps == 1


def test_a_repeated_frame_gets_the_probability_of_the_frame_it_repeats():
    """Chunk models' videos repeat each frame (and every video its last after the end): judged once."""
    judge = FrameJudge(JudgeConfig(width=16, image_size=16)).eval()
    distinct = torch.randint(0, 255, (2, 4, 16, 16, 3), dtype=torch.uint8)
    repeated = distinct.repeat_interleave(3, dim=1)  # (2, 12, ...): each frame three times
    per_frame = judge.frame_probabilities(repeated, ["open the drawer"] * 2)
    alone = torch.stack([judge.frame_probabilities(repeated[:, [0, t]], ["open the drawer"] * 2)[:, 1]
                         for t in range(1, 12)], dim=1)  # each frame judged on its own
    assert torch.allclose(per_frame[:, 1:], alone, atol=1e-3) and (per_frame[:, 0] == 0).all()
    assert torch.equal(per_frame[:, 4], per_frame[:, 5]) and torch.equal(per_frame[:, 1], per_frame[:, 2])


def test_frame_batches_are_half_successes_and_skip_frames_just_before_a_success():
    success = video([False] * 6 + [True] * 3)  # first success at frame 7
    failure = video([False] * 9, value=100)
    pool = FramePool([success, failure], ambiguous=2)
    assert sorted(pool.positives[:, 1].tolist()) == [7, 8, 9]
    negatives = {tuple(pair) for pair in pool.negatives.tolist()}
    assert (0, 5) not in negatives and (0, 6) not in negatives and (0, 4) in negatives  # 5, 6 are too close to call
    assert all((1, t) in negatives for t in range(1, 10)) and (0, 0) not in negatives  # the start frame is never used
    first, frames, texts, labels = pool.sample(10, torch.Generator().manual_seed(0))
    assert first.shape == frames.shape == (10, 8, 8, 3) and len(texts) == 10
    assert labels.sum() == 5
    assert all(int(f[0, 0, 0]) in (7, 8, 9) for f in frames[labels])  # success frames carry their index
    with pytest.raises(ValueError, match="frames with and without success"):
        FramePool([failure], ambiguous=2)


def test_hard_negatives_are_the_ones_the_judge_rates_highest_of_random_candidates():
    failure = video([False] * 40)  # frame t shows the value t: a scorer that reads it rates later frames higher
    pool = FramePool([video([False] * 6 + [True] * 3), failure], ambiguous=2)
    rated = []

    def score(first, frames, texts):
        rated.append(frames[:, 0, 0, 0].float())
        return rated[-1]

    first, frames, texts, labels = pool.sample(16, torch.Generator().manual_seed(0), hard_share=0.5, score=score)
    assert len(rated) == 1 and len(rated[0]) == 4 * HARD_CANDIDATES and labels.sum() == 8 and not labels[8:].any()
    hard = frames[12:, 0, 0, 0].float()
    assert sorted(hard.tolist()) == sorted(rated[0].topk(4).values.tolist())  # the four the scorer rated highest
    assert hard.mean() > frames[8:12, 0, 0, 0].float().mean()  # above the random negatives beside them
    with pytest.raises(ValueError, match="hard_negatives must be in"):
        JudgeTrainConfig(hard_negatives=1.5)


def test_the_threshold_separates_validation_cases():
    # Successes end bright (200+), failures dark (< 60): any threshold between separates them.
    videos = [video([False] * 20 + [True], value=190), video([False] * 21, value=30), video([False] * 21, value=10)]
    chosen = choose_threshold(Brightness(), videos)
    assert chosen["tpr"] == 1.0 and chosen["fpr"] == 0.0
    scores = [Brightness().probability(frames[None], [text]).item() for frames, text, *_ in judge_cases(videos)]
    positives = [s for s, case in zip(scores, judge_cases(videos)) if case[2]]
    negatives = [s for s, case in zip(scores, judge_cases(videos)) if not case[2]]
    assert max(negatives) < chosen["threshold"] <= min(positives)
    assert choose_threshold(Brightness(), videos[1:])["threshold"] == 0.5  # one outcome only: nothing to choose


def test_a_threshold_for_a_true_positive_rate_is_the_highest_that_keeps_it():
    # Last-frame brightness: successes 121, 171, 221, 255; failures 81, 161, 211; each success's
    # cuts (halfway and 10 short) 9 and 10 above its value: 109, 110, 159, 160, 209, 210, 249, 250.
    videos = [video([False] * 20 + [True], value=v) for v in (100, 150, 200, 240)]
    videos += [video([False] * 21, value=v) for v in (60, 140, 190)]
    every = choose_threshold(Brightness(), videos, tpr=1.0)
    assert every["threshold"] == pytest.approx((110 + 121) / 2 / 255) and every["tpr"] == 1.0
    assert every["fpr"] == round(8 / 11, 4)
    half = choose_threshold(Brightness(), videos, tpr=0.5)  # 221 and 255 pass; 211 is the score below
    assert half["threshold"] == pytest.approx((211 + 221) / 2 / 255)
    assert half["tpr"] == 0.5 and half["fpr"] == round(2 / 11, 4)
    with pytest.raises(ValueError, match="threshold_tpr"):
        dataclasses.replace(DEBUG, threshold_tpr=0.0)


def test_the_roc_readout_ranks_cases_apart_from_the_threshold():
    # Successes 0.9, 0.8, 0.4; failures 0.7, 0.3, 0.2, 0.1: 11 of the 12 pairs are ranked right.
    scores = torch.tensor([0.9, 0.8, 0.4, 0.7, 0.3, 0.2, 0.1], dtype=torch.float64)
    truth = torch.tensor([True, True, True, False, False, False, False])
    assert roc_readout(scores, truth) == {"auc": round(11 / 12, 4), "at_tpr": 0.95, "lowest_fpr": 0.25}  # 0.4 lets 0.7 in
    assert roc_readout(scores, truth, at_tpr=0.6)["lowest_fpr"] == 0.0  # 0.8 passes two successes and no failure
    tied = roc_readout(torch.full((7,), 0.5, dtype=torch.float64), truth)
    assert tied["auc"] == 0.5 and tied["lowest_fpr"] == 1.0  # ties count half; one threshold passes all
    assert roc_readout(scores, torch.ones(7, dtype=torch.bool))["auc"] is None


def test_a_learned_judges_verdicts_in_its_metrics_are_those_it_scores_with():
    videos = [video([False] * 8 + [True], value=v) for v in (40, 90, 160)] + [video([False] * 9, value=v) for v in (20, 120)]
    judge = FrameJudge(JudgeConfig(width=16, image_size=8)).eval()
    probabilities = [judge.probability(frames[None], [text]).item() for frames, text, *_ in judge_cases(videos)]
    judge.config = dataclasses.replace(judge.config, threshold=sorted(probabilities)[len(probabilities) // 2])
    report = evaluate_judge(judge, videos)
    cases = judge_cases(videos)
    said = torch.cat([judge.score(frames[None], [text]) for frames, text, *_ in cases]).bool()
    truth = torch.tensor([label for _, _, label, _, _ in cases])
    assert 0 < said.sum() < len(cases)  # the threshold splits the cases, so the rates below can be wrong
    assert report["real_tpr"] == round((said & truth).sum().item() / truth.sum().item(), 4)
    assert report["real_fpr"] == round((said & ~truth).sum().item() / (~truth).sum().item(), 4)
    assert report["real_roc"] == roc_readout(torch.tensor(probabilities, dtype=torch.float64), truth)


def test_scenes_split_three_ways_without_overlap(tiny_dataset):
    dataset = EpisodeDataset(tiny_dataset)
    train, validation, heldout = split_scenes(dataset, DEBUG)
    scenes = [{(dataset.episodes[i].task, dataset.episodes[i].seed) for i in part} for part in (train, validation, heldout)]
    assert not (scenes[0] & scenes[1]) and not (scenes[0] & scenes[2]) and not (scenes[1] & scenes[2])
    assert sorted(train + validation + heldout) == list(range(len(dataset.episodes)))


def test_the_chosen_threshold_is_saved_with_the_judge(tiny_dataset, tmp_path):
    report = train_judge(tiny_dataset, tmp_path / "judge", DEBUG, progress=False)
    judge = load_judge(tmp_path / "judge")
    assert isinstance(judge, FrameJudge) and report["kind"] == "frames"
    assert judge.config.threshold == pytest.approx(report["validation_threshold"])
    saved = json.loads((tmp_path / "judge" / "config.json").read_text())
    assert saved["model"]["threshold"] == pytest.approx(report["validation_threshold"])
    # The full preset mines hard negatives; the video judge, with no per-frame verdict to mine, ignores it.
    video = dataclasses.replace(DEBUG, kind="video", hard_negatives=0.5)
    video_kind = train_judge(tiny_dataset, tmp_path / "video", video, progress=False)
    assert video_kind["kind"] == "video" and load_judge(tmp_path / "video").backend == "embedded-judge"


def test_the_threshold_for_a_true_positive_rate_and_hard_negatives_are_train_judge_flags(tiny_dataset, tmp_path):
    from gymnast.cli import main

    main(["train-judge", "--data", str(tiny_dataset), "--out", str(tmp_path / "judge"), "--preset", "debug",
          "--threshold-tpr", "1.0", "--hard-negatives", "0.5", "--hold-steps", "2"])
    saved = json.loads((tmp_path / "judge" / "config.json").read_text())
    report = json.loads((tmp_path / "judge" / "metrics.json").read_text())
    assert saved["train"]["threshold_tpr"] == 1.0 and saved["train"]["hard_negatives"] == 0.5
    assert saved["train"]["hold_steps"] == saved["model"]["hold_steps"] == 2
    assert report["validation_tpr"] in (1.0, None)  # None: no validation scene had both outcomes


def test_a_checkpoint_of_an_unknown_judge_is_refused(tmp_path):
    from gymnast.utils.checkpoint import save_checkpoint

    save_checkpoint(tmp_path, 1, FrameJudge(JudgeConfig(width=16, image_size=16)), {"model": {"backend": "oracle"}})
    with pytest.raises(ValueError, match="model.backend is 'oracle'"):
        load_judge(tmp_path)


def test_the_committed_video_judge_still_loads():
    judge = load_judge("results/judge/video_judge")
    assert judge.backend == "embedded-judge" and judge.config.threshold == 0.5


def test_episodes_imagined_together_match_episodes_imagined_alone(tiny_dataset, tmp_path):
    from gymnast.reward.judges.videos import load_videos
    from gymnast.world_model.train import WM_PRESETS, train_world_model

    train_world_model(tiny_dataset, tmp_path / "wm", WM_PRESETS["debug"], progress=False)
    dataset = EpisodeDataset(tiny_dataset)
    episodes = list(range(len(dataset.episodes)))
    assert len({len(dataset.load(i).actions) for i in episodes}) > 1  # lengths differ: some are padded
    together = load_videos(dataset, episodes, tmp_path / "wm", progress=False)
    for i in episodes:
        real, imagined = load_videos(dataset, [i], tmp_path / "wm", progress=False)
        assert torch.equal(together[2 * i].frames, real.frames)
        assert together[2 * i + 1].imagined and imagined.frames.shape == real.frames.shape
        difference = (together[2 * i + 1].frames.float() - imagined.frames.float()).abs()
        assert difference.max() <= 2  # the same frames, up to bf16 rounding in a larger batch
