"""Rewards for rollouts: the `Reward` contract (`base`) and its implementations, chosen by name
(`spec`, `select`): the simulator's own (`sim`), VLA-RFT's verified reward (`verified`), the state
model's reward head (`state_reward`), the learned judges and their training (`judges/`), and judging
over the chat-completions protocol, a served judge and the VLM client (`chat/`)."""
