"""gymnast: train robot policies with reinforcement learning inside a learned world model."""

__version__ = "0.1.0"
