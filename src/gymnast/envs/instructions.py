"""Natural-language instructions for the 50 Meta-World v3 tasks.

Meta-World has no instruction text, so a language-conditioned policy needs ours. Each task has
two disjoint sets of paraphrases:

* ``train`` paraphrases are the only ones that ever appear in collected episodes, training data
  or world-model rollouts.
* ``heldout`` paraphrases are never used for training. Evaluating with them asks whether the
  policy understood the *request* rather than memorised a handful of exact strings. They are
  deliberately built on other sentence frames (questions, descriptions of the end state,
  requests with context), not the train sentences with one synonym swapped, so that a policy
  that only pattern-matches wording scores visibly worse on them.

Every paraphrase describes what the task's success check in metaworld/envs/ actually measures
(e.g. door-open-v3 swings the door open by its handle, not "touch the door").

Goal markers: for the tasks in `GOAL_MARKER_TASKS` success means "object or hand near a point
that is randomised per episode and marked by nothing in the scene". The rendered image shows
that point as a small green sphere, so some (never all) of those tasks' paraphrases refer to it
as the green marker/target/dot; paraphrases without it teach the policy that the marker *is*
the goal even when the words do not say so. Tasks outside the set never mention green, because
nothing green is drawn for them.

Directions: left/right are avoided on purpose. They depend on the viewpoint (window-open, for
instance, slides the pane towards +x: the robot's right, but the image's left for a camera
facing the robot across the table, like gymnast's default and Meta-World's ``corner``), so
"open"/"close", "toward the robot" and "sideways" are used instead; the verb alone already fixes
the direction.
"""

from __future__ import annotations

import difflib
import hashlib
import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

SPLITS = ("train", "heldout")


@dataclass(frozen=True)
class TaskInstructions:
    """The paraphrases of one task's instruction.

    Attributes:
        train: paraphrases that may appear in training data.
        heldout: paraphrases reserved for testing language generalisation; never trained on.
    """

    train: tuple[str, ...]
    heldout: tuple[str, ...]


GOAL_MARKER_TASKS: frozenset[str] = frozenset(
    {
        # _target_pos is drawn at random in free space (or on the bare table) every episode and
        # no scene body moves with it, so the green marker is the only way to see the goal.
        "reach-v3",  # gripper to a random 3-D point
        "reach-wall-v3",  # same, behind a wall
        "push-v3",  # puck to a random point on the table
        "push-wall-v3",  # same, around a wall
        "push-back-v3",  # block back toward the robot, to a random point
        "pick-place-v3",  # puck to a random point in the air
        "pick-place-wall-v3",  # same, over a wall
        "pick-out-of-hole-v3",  # lift the cylinder from the hole to a random point in the air
        "coffee-pull-v3",  # mug to a random point away from the machine (machine marks the start)
        "plate-slide-back-v3",  # plate out of the net to a random x in front of it (net fixed)
        "plate-slide-back-side-v3",  # plate out of the side net to a random x (net fixed)
        "sweep-v3",  # block to x=0.5 on its own row: a bare spot on the table
        "stick-push-v3",  # thermos pushed to a random y at x=0.4
        "stick-pull-v3",  # thermos pulled to a random point
        # Borderline: the target is jittered *inside* a fixed opening rather than being the
        # opening's position (hole: +-4 cm around its centre, success radius 5 cm; side net: up
        # to 6 cm off its centre, success radius 7 cm), so aiming at the opening's middle fails
        # in a few percent of episodes and the marker tells the policy exactly where to go.
        "hand-insert-v3",
        "plate-slide-side-v3",
        # Deliberately absent: shelf-place-v3 (the target is a fixed offset from the shelf,
        # which moves with it), plate-slide-v3 (the net is moved onto the target), soccer-v3
        # (the goal frame is moved onto it), coffee-push-v3 (the machine is placed over it),
        # sweep-into-v3 / bin-picking-v3 / hammer-v3 (fixed targets: hole, bin, nail) and every
        # articulated task (door, drawer, window, faucet, handle, lever, dial, button, lock,
        # peg), whose target is a fixed offset from its visible object.
    }
)


def _t(train: tuple[str, ...], heldout: tuple[str, ...]) -> TaskInstructions:
    return TaskInstructions(train=train, heldout=heldout)


_INSTRUCTIONS: dict[str, TaskInstructions] = {
    "assembly-v3": _t(
        ("Put the ring onto the peg.",
         "Pick up the nut and slide it down over the peg.",
         "Grab the ring by its handle and fit it onto the peg.",
         "Assemble the round nut onto the peg."),
        ("The ring belongs on the peg; lift it and lower it over the post until it sits there.",
         "Could you thread that round nut over the upright post?"),
    ),
    "basketball-v3": _t(
        ("Put the ball into the basketball hoop.",
         "Pick up the ball and drop it through the hoop.",
         "Score a basket with the ball.",
         "Dunk the ball into the hoop."),
        ("Make a basket: carry the ball over to the hoop and let go of it there.",
         "Can you get the ball into the net under the backboard?"),
    ),
    "bin-picking-v3": _t(
        ("Move the cube into the other bin.",
         "Pick the block out of its bin and put it in the empty bin.",
         "Transfer the block from one bin to the other.",
         "Take the cube and place it in the second bin."),
        ("The empty container should end up holding the cube.",
         "Could you shift that little block over to the bin with nothing in it?"),
    ),
    "box-close-v3": _t(
        ("Put the lid on the box.",
         "Close the box with its lid.",
         "Pick up the lid and place it on top of the box.",
         "Cover the box with the lid."),
        ("The box is open; grab the lid by its handle and seal it shut.",
         "I'd like that box covered - can you set its top back on?"),
    ),
    "button-press-topdown-v3": _t(
        ("Press the button from above.",
         "Push the button down from the top.",
         "Press down on the upward-facing button.",
         "Reach over the button and press it straight down."),
        ("Come down on that button from overhead until it is pushed in.",
         "Can you poke the button that points straight up?"),
    ),
    "button-press-topdown-wall-v3": _t(
        ("Press the button from above, reaching over the wall.",
         "Push the button down from the top; the wall is in front of it.",
         "Reach past the wall and press the button straight down.",
         "Press down on the upward-facing button behind the wall."),
        ("A low wall stands before the button box; get over it and bear down on the button.",
         "Could you reach over the barrier and jab the button facing up?"),
    ),
    "button-press-v3": _t(
        ("Press the button.",
         "Push the button in.",
         "Press the button on the front of the box.",
         "Push the button straight in, away from the robot."),
        ("That button facing the robot needs to be pushed all the way in.",
         "Can you poke the button horizontally until it's fully depressed?"),
    ),
    "button-press-wall-v3": _t(
        ("Press the button behind the wall.",
         "Push the button in, reaching around the wall.",
         "Press the button on the front of the box past the wall.",
         "Get past the wall and push the button straight in."),
        ("A wall partly blocks the button box; work your way around it and depress the button.",
         "Can you poke in the button that sits behind that little wall?"),
    ),
    "coffee-button-v3": _t(
        ("Press the coffee machine's button.",
         "Push the button on the coffee maker.",
         "Start the coffee machine by pressing its button.",
         "Press the button on the front of the coffee machine."),
        ("Brew a coffee - hit the switch on the machine.",
         "Could you push in the button on that espresso machine?"),
    ),
    "coffee-pull-v3": _t(
        ("Pull the mug out from under the coffee machine.",
         "Slide the mug away from the coffee machine to the green marker.",
         "Pull the cup over to the green target.",
         "Drag the mug out from beneath the machine to the goal."),
        ("The cup should end up on the green spot, clear of the coffee maker.",
         "Can you draw the coffee mug out from under the spout and toward you?"),
    ),
    "coffee-push-v3": _t(
        ("Push the mug under the coffee machine.",
         "Slide the cup beneath the coffee spout.",
         "Push the mug forward until it sits under the coffee machine.",
         "Put the mug under the coffee maker by pushing it."),
        ("Get the cup into position below the machine's nozzle so coffee would land in it.",
         "Can you nudge the mug over to where the coffee comes out?"),
    ),
    "dial-turn-v3": _t(
        ("Turn the dial.",
         "Rotate the knob.",
         "Twist the dial around.",
         "Grab the edge of the dial and rotate it."),
        ("The dial needs a twist; spin it to a new setting.",
         "Could you crank that round knob on the table?"),
    ),
    "disassemble-v3": _t(
        ("Take the ring off the peg.",
         "Pull the nut up and off the peg.",
         "Remove the ring from the peg.",
         "Disassemble the nut from the peg."),
        ("The round nut is sitting on the post - lift it clear of the top.",
         "Can you get that ring free of the peg it's on?"),
    ),
    "door-close-v3": _t(
        ("Close the door.",
         "Push the door shut.",
         "Swing the door closed.",
         "Shut the open door."),
        ("The door is hanging open; bring it back against its frame.",
         "Could you get that door shut for me?"),
    ),
    "door-lock-v3": _t(
        ("Lock the door.",
         "Turn the door's lock knob down.",
         "Rotate the lock on the door to the locked position.",
         "Push the lock lever down to lock the door."),
        ("Secure the door by flipping its latch downward.",
         "Can you make sure the door is locked?"),
    ),
    "door-open-v3": _t(
        ("Open the door.",
         "Pull the door open by its handle.",
         "Grab the door handle and swing the door open.",
         "Swing the door open toward the robot."),
        ("The door is shut; hook its handle and draw it wide.",
         "Can you get that door open?"),
    ),
    "door-unlock-v3": _t(
        ("Unlock the door.",
         "Turn the lock on the door to unlock it.",
         "Rotate the door's lock knob to the unlocked position.",
         "Flip the door lock open."),
        ("The door is latched; twist its lock so it's no longer locked.",
         "Can you undo the lock on that door?"),
    ),
    "drawer-close-v3": _t(
        ("Close the drawer.",
         "Push the drawer shut.",
         "Slide the drawer closed.",
         "Push the open drawer back in."),
        ("The drawer is sticking out; shove it home.",
         "Could you get that drawer shut?"),
    ),
    "drawer-open-v3": _t(
        ("Open the drawer.",
         "Pull the drawer open.",
         "Grab the drawer handle and pull it out.",
         "Slide the drawer out toward the robot."),
        ("The drawer is closed; draw it all the way out by its handle.",
         "Can you get the drawer open for me?"),
    ),
    "faucet-open-v3": _t(
        ("Open the faucet.",
         "Turn the faucet on.",
         "Rotate the tap's handle to turn it on.",
         "Swing the faucet handle to the open position."),
        ("Get the water running by twisting the tap.",
         "Could you turn on the tap?"),
    ),
    "faucet-close-v3": _t(
        ("Close the faucet.",
         "Turn the faucet off.",
         "Rotate the tap's handle to turn it off.",
         "Swing the faucet handle to the closed position."),
        ("Stop the water by twisting the tap shut.",
         "Could you turn off the tap?"),
    ),
    "hammer-v3": _t(
        ("Hammer the nail in.",
         "Pick up the hammer and drive the nail in.",
         "Use the hammer to pound the nail into the block.",
         "Grab the hammer and hit the nail."),
        ("That nail is sticking out - knock it flush with the hammer.",
         "Could you use the tool to knock that nail home?"),
    ),
    "hand-insert-v3": _t(
        ("Put the block into the hole in the table.",
         "Push the block down into the hole at the green marker.",
         "Insert the cube into the hole in the table.",
         "Move the block into the hole, onto the green target."),
        ("The cube should end up sunk in the table's opening, right at the green dot.",
         "Could you lower that block down through the gap in the tabletop?"),
    ),
    "handle-press-side-v3": _t(
        ("Press the side handle down.",
         "Push down the handle that sticks out sideways.",
         "Press down on the handle on the side of the box.",
         "Push the sideways handle all the way down."),
        ("The handle on the sideways box is up; force it downward.",
         "Could you bring the sideways-mounted handle to the bottom of its travel?"),
    ),
    "handle-press-v3": _t(
        ("Press the handle down.",
         "Push the handle down.",
         "Press down on the handle in front of the robot.",
         "Push the handle all the way down."),
        ("The handle is raised; bring it down to the bottom.",
         "Can you lower that handle as far as it will travel?"),
    ),
    "handle-pull-side-v3": _t(
        ("Pull the side handle up.",
         "Lift the handle that sticks out sideways.",
         "Raise the handle on the side of the box.",
         "Pull up on the sideways handle."),
        ("The handle on the sideways box is down; bring it up to the top.",
         "Could you raise the sideways-mounted handle to the top of its travel?"),
    ),
    "handle-pull-v3": _t(
        ("Pull the handle up.",
         "Lift the handle.",
         "Raise the handle in front of the robot.",
         "Pull up on the handle as far as it goes."),
        ("The handle is lowered; bring it up to its highest point.",
         "Could you raise that handle for me?"),
    ),
    "lever-pull-v3": _t(
        ("Pull the lever up.",
         "Lift the lever until it points straight up.",
         "Raise the lever to vertical.",
         "Push the lever upward."),
        ("The lever is lying flat; swing it up so it stands upright.",
         "Can you flip that lever up?"),
    ),
    "peg-insert-side-v3": _t(
        ("Insert the peg into the hole in the side of the box.",
         "Pick up the peg and push it into the box's side hole.",
         "Put the peg in the hole on the side of the box.",
         "Grab the peg and slide it sideways into the hole in the box."),
        ("There's an opening on the flank of the box - fit the peg into it.",
         "Could you slot the peg horizontally into that box's opening?"),
    ),
    "peg-unplug-side-v3": _t(
        ("Unplug the peg.",
         "Pull the peg out of the side of the box.",
         "Grab the peg and slide it out of the box.",
         "Remove the peg from the hole in the side of the box."),
        ("The peg is stuck in the box's flank - draw it out.",
         "Can you unplug that peg from the box?"),
    ),
    "pick-out-of-hole-v3": _t(
        ("Pick the object out of the hole.",
         "Lift the puck out of the hole and hold it at the green marker.",
         "Take the object out of the hole in the table.",
         "Grab the cylinder from the hole and raise it to the green target."),
        ("The little cylinder is down in a hole - fish it out and bring it up to the green dot.",
         "Could you retrieve the cylinder that's sunk into the table and hold it aloft?"),
    ),
    "pick-place-v3": _t(
        ("Pick up the puck and place it at the green marker.",
         "Pick and place the object.",
         "Lift the puck and move it to the green target.",
         "Grab the puck and carry it to the goal."),
        ("Carry the cylinder through the air and hold it where the green dot is.",
         "Can you move that puck over to the target by picking it up?"),
    ),
    "pick-place-wall-v3": _t(
        ("Pick up the puck and place it at the green marker behind the wall.",
         "Lift the object over the wall and put it at the goal.",
         "Pick the puck up and carry it past the wall to the green target.",
         "Move the object over the wall to the target."),
        ("There's a wall in the way; hoist the cylinder over it and bring it to the green dot.",
         "Can you get that puck to the other side of the wall by carrying it?"),
    ),
    "plate-slide-v3": _t(
        ("Slide the plate into the goal.",
         "Push the puck into the net.",
         "Slide the plate across the table into the net.",
         "Shove the plate into the goal cage."),
        ("Score by sending the flat puck gliding into the net.",
         "Could you score with the flat disc in that hockey net?"),
    ),
    "plate-slide-back-v3": _t(
        ("Slide the plate back out of the goal.",
         "Pull the plate out of the net to the green marker.",
         "Slide the puck back toward the robot to the green target.",
         "Drag the plate out of the goal and back toward the robot."),
        ("The plate is in the net; bring it back out to where the green dot is.",
         "Can you slide that puck out of the goal, back toward yourself?"),
    ),
    "plate-slide-side-v3": _t(
        ("Slide the plate sideways into the goal.",
         "Push the puck sideways into the net, onto the green marker.",
         "Slide the plate across into the net at the side.",
         "Slide the plate sideways to the green target inside the goal."),
        ("Send the flat puck gliding over into the side net, stopping on the green dot.",
         "Could you send the disc skidding across into the net off to the side?"),
    ),
    "plate-slide-back-side-v3": _t(
        ("Slide the plate sideways out of the goal.",
         "Pull the puck out of the side net to the green marker.",
         "Slide the plate out of the net and across to the green target.",
         "Drag the plate sideways away from the goal."),
        ("The plate is sitting in the side net; draw it back out to the green dot.",
         "Can you get the puck out of that goal by sliding it sideways?"),
    ),
    "push-v3": _t(
        ("Push the puck to the green marker.",
         "Push the puck to the goal.",
         "Slide the object across the table to the green target.",
         "Push the puck to the target position."),
        ("Nudge the cylinder along the tabletop until it rests on the green dot.",
         "Can you shove that puck over to the target without picking it up?"),
    ),
    "push-wall-v3": _t(
        ("Push the puck around the wall to the green marker.",
         "Push the object past the wall to the goal.",
         "Slide the puck around the wall to the green target.",
         "Push the puck to the target behind the wall."),
        ("A wall blocks the direct path; steer the cylinder around it to the green dot.",
         "Can you get the puck to the far side of the wall by pushing it along the table?"),
    ),
    "push-back-v3": _t(
        ("Push the block back toward the robot to the green marker.",
         "Pull the block back to the goal.",
         "Slide the block back toward the robot to the green target.",
         "Drag the cube backward to the target position."),
        ("Bring the cube in closer, sliding it along the table until it sits on the green dot.",
         "Can you slide that block back in the direction of the robot?"),
    ),
    "reach-v3": _t(
        ("Reach to the green marker.",
         "Move the gripper to the goal.",
         "Move your hand to the green target.",
         "Put the gripper at the target position."),
        ("Bring your fingertips to where the green dot floats.",
         "Can you move the hand over to the target point?"),
    ),
    "reach-wall-v3": _t(
        ("Reach over the wall to the green marker.",
         "Move the gripper past the wall to the goal.",
         "Reach around the wall to the green target.",
         "Move your hand to the target behind the wall."),
        ("There's a wall between you and the green dot; get your gripper to it anyway.",
         "Can you put your hand on the target point on the other side of the wall?"),
    ),
    "shelf-place-v3": _t(
        ("Place the block on the shelf.",
         "Put the cube on the shelf.",
         "Pick up the block and set it on the shelf.",
         "Lift the cube onto the middle of the shelf."),
        ("Store the little block up on the shelf unit, in the centre.",
         "Could you tidy that block away onto the shelving unit?"),
    ),
    "soccer-v3": _t(
        ("Kick the ball into the goal.",
         "Push the soccer ball into the net.",
         "Score a goal with the ball.",
         "Roll the ball into the goal."),
        ("Get the football over the line and into the net.",
         "Can you knock the ball in between the goalposts?"),
    ),
    "stick-pull-v3": _t(
        ("Use the stick to pull the thermos to the green marker.",
         "Grab the stick, hook it through the thermos handle and drag it to the goal.",
         "Pull the container with the stick to the green target.",
         "Insert the stick into the thermos handle and pull the thermos."),
        ("With the rod looped through the flask's handle, haul the flask over to the green dot.",
         "Can you fetch that container using the stick as a tool?"),
    ),
    "stick-push-v3": _t(
        ("Use the stick to push the thermos to the green marker.",
         "Pick up the stick and push the container with it.",
         "Push the container to the goal with the stick.",
         "Grab the stick and shove the thermos to the green target."),
        ("Holding the stick, poke the bottle along until it reaches the green dot.",
         "Can you move that container away by pushing it with the stick?"),
    ),
    "sweep-into-v3": _t(
        ("Sweep the block into the hole.",
         "Push the cube into the hole in the table.",
         "Slide the block into the hole.",
         "Sweep the cube across the table into the hole."),
        ("Brush the little block along until it drops through the opening in the table.",
         "Can you knock that cube into the hole?"),
    ),
    "sweep-v3": _t(
        ("Sweep the block to the green marker.",
         "Push the cube sideways across the table to the goal.",
         "Slide the block along the table to the green target.",
         "Sweep the cube over to the target."),
        ("Drag the block far along its row on the table and stop it on the green dot.",
         "Could you brush that cube across the tabletop to where it's supposed to go?"),
    ),
    "window-open-v3": _t(
        ("Open the window.",
         "Slide the window open.",
         "Push the window sideways to open it.",
         "Slide the window pane open along its track."),
        ("Let some fresh air in by sliding the window across.",
         "Can you pull the pane across so the window is no longer shut?"),
    ),
    "window-close-v3": _t(
        ("Close the window.",
         "Slide the window shut.",
         "Push the window sideways to close it.",
         "Slide the window pane closed along its track."),
        ("The window is open; slide it back until it's shut.",
         "Can you seal the gap by bringing the pane all the way across?"),
    ),
}

INSTRUCTIONS: Mapping[str, TaskInstructions] = MappingProxyType(_INSTRUCTIONS)
"""Task name -> its paraphrases. Read-only so that no caller can leak a held-out string into
the train split at run time."""

TASKS: tuple[str, ...] = tuple(sorted(INSTRUCTIONS))


def _lookup(task: str) -> TaskInstructions:
    try:
        return INSTRUCTIONS[task]
    except KeyError:
        # cutoff=0 always yields the nearest name, which catches the common slips
        # (missing "-v3", v2 names, typos) without the caller reading all 50 names.
        closest = difflib.get_close_matches(task, TASKS, n=1, cutoff=0.0)
        hint = f" Did you mean {closest[0]!r}?" if closest else ""
        raise ValueError(
            f"Unknown Meta-World v3 task {task!r}.{hint} Valid tasks: {', '.join(TASKS)}"
        ) from None


def all_instructions(task: str, split: str = "train") -> tuple[str, ...]:
    """Returns every paraphrase of a task's instruction in one split.

    Args:
        task: Meta-World v3 task name, e.g. ``drawer-open-v3``.
        split: ``train`` or ``heldout``.

    Returns:
        The split's paraphrases, in a fixed order.

    Raises:
        ValueError: if the task or the split is unknown.
    """
    entry = _lookup(task)
    if split not in SPLITS:
        raise ValueError(f"Unknown split {split!r}; expected one of {SPLITS}")
    return entry.train if split == "train" else entry.heldout


def instruction_for(task: str, seed: int, split: str = "train") -> str:
    """Picks one paraphrase of a task's instruction, deterministically from a seed.

    The same (task, seed, split) gives the same string in every process and on every machine,
    so a recorded episode's instruction can be recomputed from its seed.

    Args:
        task: Meta-World v3 task name, e.g. ``drawer-open-v3``.
        seed: any integer, typically the episode's environment seed.
        split: ``train`` or ``heldout``.

    Returns:
        One of ``all_instructions(task, split)``.

    Raises:
        ValueError: if the task or the split is unknown.
        TypeError: if the seed is not an integer.
    """
    return pick_sentence(all_instructions(task, split), f"{task}|{split}", seed)


def pick_sentence(options: Sequence[str], key: str, seed: int) -> str:
    """One of `options`, chosen by (`key`, `seed`) the same way in every process and machine."""
    seed = operator.index(seed)
    # hash() is salted per process (PYTHONHASHSEED), so use a fixed digest. Mixing in the key (the
    # task) keeps seed s from choosing the same position (e.g. the plainest wording) for every task.
    digest = hashlib.blake2b(f"{key}|{seed}".encode(), digest_size=8).digest()
    return options[int.from_bytes(digest, "big") % len(options)]


def read_sentences(path: str | Path) -> dict[str, tuple[str, ...]]:
    """A user's own instructions: a text file of ``task: sentence`` lines (several per task
    allowed; blank lines and lines starting with ``#`` are skipped).

    Raises:
        FileNotFoundError: no such file.
        ValueError: a line that is not ``task: sentence``, an unknown task or an empty sentence
            (the message names the file and the line), or a file with no sentences.
    """
    path = Path(path)
    sentences: dict[str, list[str]] = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        task, colon, sentence = line.partition(":")
        where = f"{path}, line {number}"
        if not colon:
            raise ValueError(f"{where}: expected 'task: sentence', got {line!r}")
        if not sentence.strip():
            raise ValueError(f"{where}: the sentence for {task.strip()!r} is empty")
        try:
            _lookup(task.strip())
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
        sentences.setdefault(task.strip(), []).append(sentence.strip())
    if not sentences:
        raise ValueError(f"{path}: no 'task: sentence' lines")
    return {task: tuple(options) for task, options in sentences.items()}
