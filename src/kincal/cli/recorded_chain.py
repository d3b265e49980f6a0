"""The chain a FRAMES.json records, for the commands that read one (evaluate, compensate).

Frames identified for one chain mean nothing for another: the tool point lives in the
recorded tip frame, the measurement frame is placed against the recorded base. Base and
tip default to the recorded ones, another ``--base``/``--tip`` is refused, and a robot
without the recorded frames is named as frames of another robot (not as an unknown base
frame the user never typed)."""

from __future__ import annotations

import dataclasses

from kincal.cli.options import Chain
from kincal.errors import FrameError


def chain_from_frames(chain: Chain, frames) -> Chain:
    """The chain with base and tip from FRAMES.json where not given; refuse a mismatch."""
    for role in ("base", "tip"):
        recorded, given = getattr(frames, f"{role}_frame"), getattr(chain, role)
        if not recorded:
            continue  # an older frames file without the chain: nothing to check
        if given is None:
            chain = dataclasses.replace(chain, **{role: recorded})
        elif given != recorded:
            held = frames.chains() or ((frames.base_frame, frames.tip_frame),)
            raise FrameError(f"--{role} {given!r} does not match the {role} frame {recorded!r} "
                             f"recorded in {frames.source} (its frames were identified for "
                             f"{', '.join(f'{b} -> {t}' for b, t in held)}); "
                             + (f"use --{role} {recorded}" if len(held) == 1 else
                                "give --base and --tip of one of them")
                             + " or frames identified for this chain", valid=(recorded,))
    return chain


def load_recorded(chain: Chain, frames):
    """The robot of ``chain`` (from :func:`chain_from_frames`; frames None: as given). A
    recorded base or tip this robot lacks (UR10 frames, ``world -> tool0``, on an EC66) is
    refused as frames of another robot or chain."""
    try:
        return chain.load()
    except FrameError as exc:
        recorded = () if frames is None else (frames.base_frame, frames.tip_frame)
        if not any(f and f in (chain.base, chain.tip) for f in recorded):
            raise
        of = f" of the robot {frames.robot!r}" if frames.robot else ""
        raise FrameError(f"{frames.source} holds frames{of} identified on the chain "
                         f"{' -> '.join(recorded)}, which {chain.robot} does not have: frames "
                         f"of another robot or chain would give wrong numbers ({exc})",
                         valid=exc.valid) from None
