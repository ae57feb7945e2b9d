"""Environments: the Meta-World "real world", its software-simulator variants, and (later) the
imagined environment over a learned world model."""
