"""Episodes for world-model training and evaluation: the held-out split and an in-memory bank.

Legend: B batch, C context frames, F future frames, H/W image size, A action dimensions.

The split is by scene, not by episode: every episode of a (task, seed) layout goes to the same
side, because the experts, noisy experts and failures recorded on one seed share the scene, and
a model evaluated on a scene it trained on would look better than it is. Episodes from
evaluation seeds (`gymnast.envs.tasks.EVAL_SEEDS`) are never used at all.
"""

from __future__ import annotations

import dataclasses
import logging
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from tqdm import tqdm

from gymnast.data.lerobot import EpisodeDataset
from gymnast.data.schema import EpisodeInfo
from gymnast.envs.tasks import EVAL_SEEDS

logger = logging.getLogger(__name__)


def is_heldout(info: EpisodeInfo, fraction: float) -> bool:
    """Whether the episode's scene (task, seed) belongs to the held-out part (a fixed hash)."""
    return zlib.crc32(f"{info.task}/{info.seed}".encode()) % 10_000 < fraction * 10_000


def usable_episodes(infos: Sequence[EpisodeInfo]) -> list[int]:
    """The indices of the episodes not recorded on evaluation seeds: nothing may learn from or
    tune on the scenes the policies are finally judged in."""
    usable = [i for i, info in enumerate(infos) if info.seed not in EVAL_SEEDS]
    if len(usable) < len(infos):
        logger.warning("ignoring %d episodes recorded on evaluation seeds", len(infos) - len(usable))
    return usable


def split_episodes(infos: Sequence[EpisodeInfo], fraction: float) -> tuple[list[int], list[int]]:
    """(train, held-out) episode indices; episodes recorded on evaluation seeds are in neither."""
    if not 0 <= fraction < 1:
        raise ValueError(f"the held-out fraction must be in [0, 1), got {fraction}")
    usable = usable_episodes(infos)
    heldout = [i for i in usable if is_heldout(infos[i], fraction)]
    return [i for i in usable if i not in set(heldout)], heldout


@dataclass(frozen=True)
class ClipBatch:
    """Clips for training: C context frames, then F future frames and the F actions leading to them.

    Attributes:
        context: (B, C, H, W, 3) uint8.
        actions: (B, F, A) float32; action f moves frame C-1+f to frame C+f.
        future: (B, F, H, W, 3) uint8.
        states: (B, F, S) float32 the recorded state of each future frame (what a grounded model
            renders it at); S = 0 where the episodes record none.
    """

    context: torch.Tensor
    actions: torch.Tensor
    future: torch.Tensor
    states: torch.Tensor


class EpisodeBank:
    """Decoded episodes held in memory (about 28 KB per 96 px frame) for fast random clips.

    Training draws clips from anywhere in the dataset at every step, so decoding on demand (as
    `gymnast.data.windows.TrainingWindows` does for datasets too large for memory) would decode
    a whole episode per clip; MT10 with 30 episodes per task fits in about 1 GB.

    A dataset read with several cameras gives one entry per camera of each episode, under the
    episode's actions: a single-view model learns every camera's view from them
    (`gymnast.world_model.views`).

    Args:
        dataset: where the episodes are (each of its cameras read).
        indices: which episodes to load.
        progress: show a progress bar while decoding.

    Attributes (one per entry, an episode's cameras consecutive):
        indices: the episode's index in its dataset.
        roots: its dataset directory (banks may hold several datasets, see `union`).
        cameras: the camera whose frames the entry holds.
        infos, frames, actions: the episode's facts, the camera's (T+1, H, W, 3) uint8 frames and
            the episode's (T, A) actions.
        states: the episode's (T+1, S) float32 states: its environment state where recorded (the
            objects' too), else its ``observation.state``, as the state model reads them.
    """

    def __init__(self, dataset: EpisodeDataset, indices: Sequence[int], progress: bool = False) -> None:
        if not indices:
            raise ValueError(f"{dataset.root}: no episodes to load (is the held-out fraction too large?)")
        self.indices, self.roots, self.cameras, self.infos, self.frames, self.actions = [], [], [], [], [], []
        self.states = []
        for i in tqdm(indices, desc="loading episodes", disable=not progress):
            episode = dataset.load(i)
            actions = torch.from_numpy(episode.actions).float()  # (T, A)
            states = torch.from_numpy(episode.full_states).float()
            for camera, frames in (episode.views or {dataset.camera_key: episode.frames}).items():
                self.indices.append(i)
                self.roots.append(dataset.root)
                self.cameras.append(camera)
                self.infos.append(dataset.episodes[i])
                self.frames.append(torch.from_numpy(frames))  # (T+1, H, W, 3)
                self.actions.append(actions)
                self.states.append(states)

    @classmethod
    def union(cls, parts: Sequence[tuple[EpisodeDataset, Sequence[int]]], progress: bool = False) -> EpisodeBank:
        """One bank over the chosen episodes of several datasets, in order; datasets with none are skipped.

        Raises:
            ValueError: no dataset has an episode chosen.
        """
        banks = [cls(dataset, indices, progress) for dataset, indices in parts if indices]
        if not banks:
            roots = ", ".join(str(dataset.root) for dataset, _ in parts)
            raise ValueError(f"{roots}: no episodes to load (is the held-out fraction too large?)")
        bank = banks[0]
        for other in banks[1:]:
            for name in ("indices", "roots", "cameras", "infos", "frames", "actions", "states"):
                getattr(bank, name).extend(getattr(other, name))
        return bank

    def __len__(self) -> int:
        return len(self.indices)

    def clip(self, k: int, start: int, context: int, future: int) -> ClipBatch:
        """The clip of episode `k` (position in this bank) whose first context frame is `start`.

        `start` may be negative down to 1 - C: frames before the episode repeat its first frame
        and the actions between them are zero, which is exactly a robot standing still. This
        teaches the model to start from a single real frame, as RL rollouts do.
        """
        frames, actions = self.frames[k], self.actions[k]
        steps = len(actions)
        if not 1 - context <= start <= steps + 1 - context - future:
            raise IndexError(f"clip start {start} is outside episode {self.indices[k]} of {self.roots[k]} ({steps} steps)")
        index = torch.arange(start, start + context + future).clamp(min=0)
        action_index = torch.arange(start + context - 1, start + context - 1 + future)
        clip_actions = torch.where((action_index >= 0)[:, None], actions[action_index.clamp(min=0)], 0.0)
        clip_frames = frames[index]
        return ClipBatch(clip_frames[None, :context], clip_actions[None], clip_frames[None, context:],
                         self.states[k][index[context:]][None])

    def sample(self, batch: int, context: int, future: int, generator: torch.Generator) -> ClipBatch:
        """`batch` clips drawn uniformly over episodes, then over start positions."""
        eligible = [k for k, a in enumerate(self.actions) if len(a) + 1 >= future + 1]
        if not eligible:
            raise ValueError(f"no episode has the {future + 1} frames a clip of {future} future frames needs")
        clips = []
        for _ in range(batch):
            k = eligible[int(torch.randint(len(eligible), (1,), generator=generator))]
            last_start = len(self.actions[k]) + 1 - context - future
            start = int(torch.randint(1 - context, last_start + 1, (1,), generator=generator))
            clips.append(self.clip(k, start, context, future))
        widths = {c.states.shape[-1] for c in clips}
        if len(widths) > 1:  # only a grounded model reads them; the others train on any mix
            clips = [dataclasses.replace(c, states=c.states[..., :0]) for c in clips]
        return ClipBatch(*(torch.cat(parts) for parts in zip(*((c.context, c.actions, c.future, c.states) for c in clips))))

    def state_stats(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(S,) mean and spread of every recorded state in the bank, which a grounded model
        normalises its state input by (a spread of 0, a number that never changes, counts as 1).

        Raises:
            ValueError: the episodes record no state, or states of different widths.
        """
        widths = {states.shape[1] for states in self.states}
        if len(widths) != 1 or 0 in widths:
            roots = ", ".join(sorted({str(root) for root in self.roots}))
            raise ValueError(f"{roots}: a grounded world model needs every episode to record a state of one width "
                             f"(observation.environment_state or observation.state); found widths {sorted(widths)}")
        everything = torch.cat(self.states)
        spread = everything.std(dim=0)
        spread = torch.where(spread > 1e-6, spread, torch.ones_like(spread))
        return tuple(everything.mean(dim=0).tolist()), tuple(spread.tolist())
